"""Stage: markdown reports with PNG figures, regenerated from `vintix eval` results."""

from vintix.report.report import load_results, write_report

__all__ = ["load_results", "write_report"]
