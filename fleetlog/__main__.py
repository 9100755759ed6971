"""``python -m fleetlog`` runs the CLI."""

from fleetlog.cli import main

main()
