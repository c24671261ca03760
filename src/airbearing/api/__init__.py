"""Library functions behind the front door ``import airbearing as ab``.

Each module here holds a decision that used to live only in the command line (which
identifier runs, the ``log check`` summary), so that the CLI, the campaign adapters and a
notebook call the same function. Nothing here imports a numerical library at import time.
"""
