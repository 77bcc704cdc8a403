"""`python -m logscan` runs the CLI."""

from logscan.cli.main import main

main()
