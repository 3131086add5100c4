"""`python -m app.cli`: the `ltaa` command from a checkout (the tests start the simulator so)."""

from app.cli import main

main()
