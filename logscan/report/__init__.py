"""The HTML analysis report: detector results -> figure specs -> plotly JSON -> one offline page."""

from logscan.report.page import ReportInput, flat_alarms, render_html, render_report, report_matches

__all__ = ["ReportInput", "flat_alarms", "render_html", "render_report", "report_matches"]
