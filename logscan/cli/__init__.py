"""Command-line interface of logscan (click)."""

from logscan.memory import reuse_freed_arrays

# a command-line run owns its process: freed arrays are reused from the heap, the largest returned
reuse_freed_arrays()
