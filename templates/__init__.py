"""Jinja2 templates of logscan's reports (installed as ``logscan.templates``)."""
