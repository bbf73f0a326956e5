"""mc: sampling and Monte Carlo ensembles of the true sampled impact systems."""

from mc._checkpoint import checkpoint_for, checkpoint_lifetime, remove_checkpoint
from mc._control import cv_estimates
from mc._ensemble import simulate_mc
from opa.engine import DaskError, check_scheduler_address, connect_scheduler
from mc._source import sweep_source
from mc._sampling import SAMPLERS, sample_xi, semicircle_cdf, semicircle_ppf

__all__ = [
    "simulate_mc",
    "connect_scheduler",
    "check_scheduler_address",
    "remove_checkpoint",
    "checkpoint_for",
    "checkpoint_lifetime",
    "DaskError",
    "sample_xi",
    "semicircle_cdf",
    "semicircle_ppf",
    "SAMPLERS",
    "sweep_source",
    "cv_estimates",
]
