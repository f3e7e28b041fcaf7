"""Analyses end to end: one stack into a results folder with its report
(:func:`analyse_to_folder`), or many at once, locally or on a Dask cluster
(:func:`run_batch`, ``batch_summary.csv``)."""

from ..core.lazy import attach

__getattr__, __dir__, __all__ = attach(__name__, submodules=("runner", "summary", "executors"),
                                       submod_attrs={
                                           "runner": ["BatchInterrupted", "BatchResult",
                                                      "analyse_to_folder", "open_stack",
                                                      "run_batch"],
                                           "summary": ["SUMMARY_COLUMNS", "result_names"]})
