"""Command-line interface of logscan (click)."""

import os

from logscan.memory import reuse_freed_arrays

# a command-line run owns its process: freed arrays are reused from the heap, the largest returned
reuse_freed_arrays()
# and its matrices are small (a state of at most a few dozen): OpenBLAS's worker threads would
# only spin beside the one computing (0.25 s of CPU in a 1-hour log's 6). Set before numpy is
# imported, which reads it once; a user's own setting wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
