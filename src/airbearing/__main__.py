"""``python -m airbearing``: the same as the ``airbearing`` command."""

from airbearing.cli import main

main()
