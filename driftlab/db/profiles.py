"""Stored car profiles (driftlab.db.models.CarProfile): added by ``driftlab calibrate``, read when a job of that car
is created."""

from __future__ import annotations

from typing import Any

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from driftlab.db.models import CarProfile
from driftlab.db.storage import get_row


def add_profile(session: Session, *, plant_model: str, vehicle_id: int, document: dict[str, Any]) -> CarProfile:
    profile = CarProfile(plant_model=plant_model, vehicle_id=vehicle_id, document=document)
    session.add(profile)
    session.flush()
    return profile


def car_profiles(session: Session, *, plant_model: str, vehicle_id: int) -> list[CarProfile]:
    """Every profile of one car, oldest first."""
    return list(session.scalars(select(CarProfile).where(CarProfile.plant_model == plant_model,
                                                         CarProfile.vehicle_id == vehicle_id)
                                .order_by(CarProfile.id)))


def newest_profiles(session: Session) -> list[CarProfile]:
    """The newest profile of each car (plant model, vehicle), newest first."""
    newest = (select(func.max(CarProfile.id)).group_by(CarProfile.plant_model, CarProfile.vehicle_id)
              .scalar_subquery())
    return list(session.scalars(select(CarProfile).where(CarProfile.id.in_(newest)).order_by(CarProfile.id.desc())))


def get_profile(session: Session, *, profile_id: int) -> CarProfile:
    return get_row(session, CarProfile, profile_id, "car profile")


def list_profiles(session: Session) -> list[CarProfile]:
    return list(session.scalars(select(CarProfile).order_by(CarProfile.id)))
