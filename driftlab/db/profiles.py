"""Stored car profiles (driftlab.db.models.CarProfile): added by ``driftlab calibrate``, read when a job of that car
is created."""

from __future__ import annotations

from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from driftlab.db.models import CarProfile
from driftlab.db.storage import NotFound


def add_profile(session: Session, *, plant_model: str, vehicle_id: int, document: dict[str, Any]) -> CarProfile:
    profile = CarProfile(plant_model=plant_model, vehicle_id=vehicle_id, document=document)
    session.add(profile)
    session.flush()
    return profile


def latest_profile(session: Session, *, plant_model: str, vehicle_id: int) -> CarProfile | None:
    return session.scalar(select(CarProfile).where(CarProfile.plant_model == plant_model,
                                                   CarProfile.vehicle_id == vehicle_id)
                          .order_by(CarProfile.id.desc()).limit(1))


def get_profile(session: Session, *, profile_id: int) -> CarProfile:
    profile = session.get(CarProfile, profile_id)
    if profile is None:
        raise NotFound(f"no car profile {profile_id}")
    return profile


def list_profiles(session: Session) -> list[CarProfile]:
    return list(session.scalars(select(CarProfile).order_by(CarProfile.id)))
