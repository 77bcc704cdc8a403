"""Command-line interface of logscan (click)."""

from logscan.memory import return_freed_arrays_to_the_system

# a command-line run owns its process: large arrays freed between phases go back to the system
return_freed_arrays_to_the_system()
