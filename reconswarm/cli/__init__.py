"""What every command of the command line shares: one-line errors and exit codes (console), how help shows
options (help_style), output paths (outputs), and the zenoh options and process wrapper of the process commands
(options). The roles' commands (agent/cli.py, simworld/cli.py, monitor/cli.py) and the top floor's
(reconswarm_bringup/cli*.py) are built on it."""
