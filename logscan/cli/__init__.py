"""Command-line interface of logscan (click)."""
