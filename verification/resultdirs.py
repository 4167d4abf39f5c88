"""Names of :mod:`edem.resultdir` (the result-directory module) under their former module."""

from edem.resultdir import non_finite_count, read_result_dir, read_surface_frame, read_timeseries_csv, write_surface_frame

__all__ = ["non_finite_count", "read_result_dir", "read_surface_frame", "read_timeseries_csv", "write_surface_frame"]
