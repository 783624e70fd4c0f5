"""Calibrations (as ``driftlab calibrate``: queued, run by the job runner, followed, cancelled) and the car
profiles they store."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Depends, HTTPException, Path, Request, Response
from pydantic import BaseModel, ConfigDict, Field
from sqlalchemy.orm import Session, sessionmaker

from driftlab.core.calibration_request import LIMITS, CalibrationRequest
from driftlab.core.config import dotted_config
from driftlab.core.configure import PLANT_PRESETS
from driftlab.core.plants import installed_names
from driftlab.server import quotas
from driftlab.server.responses import Calibration, ProfileSummary, errors
from driftlab.server.routes.deps import factory, require_token, wake_runner
from driftlab.server.schemas import PruneCreate, check_document_types
from driftlab.services import calibration_queue
from driftlab.services.profiles import list_profile_summaries, profile_document

router = APIRouter(tags=["calibration"])
Factory = Annotated[sessionmaker[Session], Depends(factory)]
RowId = Annotated[int, Path(ge=1, le=2**63 - 1)]
PLANT_CHOICES = (*PLANT_PRESETS, *installed_names())
PlantName = Literal[PLANT_CHOICES]  # type: ignore[valid-type]  # the presets and the plants installed
NUMBER = r"\d+(\.\d+)?"
POINTS_PATTERN = rf"^(\s*{NUMBER}@{NUMBER}\s*)(,\s*{NUMBER}@{NUMBER}\s*)*$"


class ThetaGiven(BaseModel):
    """Any subset of theta (the others untuned)."""

    model_config = ConfigDict(extra="forbid")

    c_lr: float | None = Field(default=None, strict=True)
    c_rl: float | None = Field(default=None, strict=True)
    dV: float | None = Field(default=None, strict=True)  # noqa: N815  # theta's own name (paper eq. 10)
    k: float | None = Field(default=None, strict=True)
    model_mu_scale: float | None = Field(default=None, strict=True)
    model_c_scale: float | None = Field(default=None, strict=True)


class CalibrationCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    plant: PlantName = Field(description="a plant preset, as `--plant` (e.g. commonroad_std)")
    config: dict[str, Any] = Field(default_factory=dict, description="dotted config keys, as `--set` (e.g. "
                                   "plant.commonroad_vehicle: 3, scenario.sideslip_rad: 0.55)")
    points: str | None = Field(default=None, max_length=400, pattern=POINTS_PATTERN,
                               description="SIDESLIP@RADIUS,... (default: the "
                               "scenario's drift and every 0.05 rad either side of it across the car's drift window "
                               "on its circle, its sideslip on circles 30/44 and 52/44 the size)")
    iterations: int = Field(default=150, ge=LIMITS["iterations"][0], le=LIMITS["iterations"][1], strict=True)
    seeds: int = Field(default=3, ge=LIMITS["seeds"][0], le=LIMITS["seeds"][1], strict=True)
    seed: int = Field(default=0, ge=0, le=2**31 - 1, strict=True)
    rounds: int = Field(default=1, ge=LIMITS["rounds"][0], le=LIMITS["rounds"][1], strict=True)
    one_set: bool = Field(default=False, strict=True)
    theta: ThetaGiven = Field(default_factory=ThetaGiven, description="the theta every weight set drives (any "
                              "subset; default the untuned one)")
    prune: PruneCreate | None = Field(default=None, description="stop a weight set whose first seeds are worse than "
                                      "the best set's on the same seeds with confidence (default: on, 0.95, 2 seeds)")


@router.post("/api/calibrations", status_code=202, dependencies=[Depends(require_token)],
             response_model=Calibration, responses=errors(409, 422, 503))
def start_calibration(body: CalibrationCreate, db: Factory, request: Request) -> dict[str, Any]:
    """Queue a calibration of a car, as `driftlab calibrate` runs it: the job runner runs it beside the jobs, on
    its share of the workers; every profile it finds is stored as it is found, and the jobs of that car take it.
    Follow it with GET, stop it with DELETE. 409 while another calibration is queued or running."""
    check_document_types({"config": body.config})
    quotas.check_calibration(request.app.state.settings, points=len(body.points.split(",")) if body.points else None,
                             iterations=body.iterations, seeds=body.seeds, rounds=body.rounds)
    calibration = CalibrationRequest(plant=body.plant, sets=dotted_config(body.config), points=body.points,
                                     iterations=body.iterations, seeds=body.seeds, seed=body.seed,
                                     rounds=body.rounds, one_set=body.one_set,
                                     theta=body.theta.model_dump(exclude_none=True),
                                     prune=body.prune.model_dump() if body.prune is not None else {},
                                     command=f"POST /api/calibrations {body.model_dump_json(exclude_defaults=True)}")
    try:
        out = calibration_queue.queue(db, calibration)
    except calibration_queue.CalibrationBusy as exc:
        raise HTTPException(409, str(exc)) from None
    wake_runner(request)
    return out


@router.get("/api/calibrations", response_model=list[Calibration], responses=errors(503))
def list_calibrations(db: Factory) -> list[dict[str, Any]]:
    return calibration_queue.listing(db)


@router.get("/api/calibrations/{calibration_id}", response_model=Calibration, responses=errors(404, 422, 503))
def get_calibration(calibration_id: RowId, db: Factory) -> dict[str, Any]:
    """Queued, running (its ``progress``), finished (its ``profile_ids``), failed (``error``) or cancelled."""
    return calibration_queue.status(db, calibration_id)


@router.delete("/api/calibrations/{calibration_id}", dependencies=[Depends(require_token)],
               response_model=Calibration, responses=errors(404, 422, 503))
def cancel_calibration(calibration_id: RowId, db: Factory) -> dict[str, Any]:
    """Stop a queued or running calibration (the profiles it stored stay); 404 if it is neither."""
    return calibration_queue.cancel(db, calibration_id)


@router.get("/api/profiles", response_model=list[ProfileSummary], responses=errors(503))
def list_profiles(db: Factory) -> list[dict[str, Any]]:
    """Every stored car profile, oldest first (a job records the one it took as ``profile_id``)."""
    return list_profile_summaries(db)


@router.get("/api/profiles/{profile_id}", responses=errors(404, 422, 503))
def get_profile(profile_id: RowId, db: Factory, response: Response) -> dict[str, Any]:
    """The whole profile, as `driftlab calibrate --out` writes one: the weights, the model, the figures per
    point, the known sets, the window, the command. A file to keep or share."""
    response.headers["Content-Disposition"] = f'attachment; filename="driftlab-profile-{profile_id}.json"'
    return profile_document(db, profile_id)
