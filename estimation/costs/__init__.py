"""Cost functions of the thesis, vectorised over optimiser populations.

Every function compares a *target* (measured or reference data, 1-D along
the last axis) with an *estimate* of the same length along the last axis;
the estimate may carry leading population dimensions ``(P, ...)``. Results
have the estimate's leading shape: ``(P,)`` for a population, a 0-d array
for a single estimate.

- :mod:`estimation.costs.metrics` -- MSE (2.21), MAE (2.22), RMSE (2.23),
  MAPE (2.24), NRMSE (2.25)-(2.26), Pearson correlation (2.27), the
  correlation cost of (4.31), (4.34), and the time-domain costs
  ``C^v_rmse`` (4.32)-(4.33), ``C^v_rho`` (4.34);
- :mod:`estimation.costs.frequency` -- log-magnitude error (4.20), (4.30),
  (5.9), its sum of squares (4.21), ``C^z_rmse`` (4.29), ``C^z_rho``
  (4.31), ``C_wnrmse`` with the band weights (5.8)-(5.11) of Table 5.1;
- :mod:`estimation.costs.emd` -- ``C^m_nrmse`` (4.39)-(4.41), ``C^m_rho``
  (4.42), ``C^i_nrmse`` (4.45), ``C^i_rho`` (4.46) on the inferred IMFs (4.43);
- :mod:`estimation.costs.objects` -- :class:`CostFunction` objects that an
  estimation loop calls as ``cost(target, estimate_population) -> (P,)``.

The names below are this package's public namespace.
"""

from __future__ import annotations

from estimation.costs.emd import (EMD_METHODS, Decomposer, emd_correlation, emd_nrmse, iemd_correlation, iemd_nrmse,
    imf_ranges, inferred_imfs, pad_sets, truncate_sets)
from estimation.costs.frequency import (ESTIMATION_BAND, LVSC_OMIT_BELOW, TABLE_5_1_BANDS, band_weights,
    log_magnitude_error, log_magnitude_sse, omit_below, response_range, thesis_masks, wnrmse, z_correlation, z_rmse)
from estimation.costs.metrics import (correlation_cost, mae, mape, mse, nrmse_mean, nrmse_range, pearson, rmse,
    v_correlation, v_rmse)
from estimation.costs.objects import (CorrelationCost, CostFunction, EMDCost, IEMDCost, LogMagnitudeCost, TimeCost,
    WNRMSECost, penalise)

__all__ = ["TABLE_5_1_BANDS", "ESTIMATION_BAND", "LVSC_OMIT_BELOW", "EMD_METHODS", "mse", "mae", "rmse", "mape", "nrmse_mean", "nrmse_range", "pearson", "correlation_cost", "log_magnitude_error", "log_magnitude_sse", "z_rmse", "z_correlation", "band_weights", "omit_below", "thesis_masks", "response_range", "wnrmse", "v_rmse", "v_correlation", "Decomposer", "pad_sets", "truncate_sets", "imf_ranges", "emd_nrmse", "emd_correlation", "inferred_imfs", "iemd_nrmse", "iemd_correlation", "CostFunction", "LogMagnitudeCost", "CorrelationCost", "WNRMSECost", "TimeCost", "EMDCost", "IEMDCost", "penalise"]
