"""mc: sampling and Monte Carlo ensembles of the true sampled impact systems."""

from mc._ensemble import simulate_mc
from mc._sampling import SAMPLERS, sample_xi, semicircle_cdf, semicircle_ppf

__all__ = ["simulate_mc", "sample_xi", "semicircle_cdf", "semicircle_ppf", "SAMPLERS"]
