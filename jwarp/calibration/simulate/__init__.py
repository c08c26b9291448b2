"""Simulated calibration campaigns: true robots, scenarios, unmodelled effects
(thesis 2.6)."""

from jwarp.calibration.simulate.campaign import (
    Campaign,
    read_campaign,
    simulate_campaign,
)
from jwarp.calibration.simulate.scenarios import scenario
from jwarp.calibration.simulate.unmodeled import Unmodeled, add_unmodeled

__all__ = [
    "Campaign", "Unmodeled", "add_unmodeled", "read_campaign", "scenario",
    "simulate_campaign",
]
