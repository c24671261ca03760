"""Monte Carlo campaigns: one command run many times on dispersed testbeds, on Dask.

:mod:`.spec` reads the campaign file, :mod:`.dispersions` draws each run,
:mod:`.adapters` runs each command, :mod:`.runner` schedules the runs and
:mod:`.results` keeps the rows (Parquet parts, then the results file).
"""

from airbearing.analysis.campaign.runner import open_client, run_campaign, run_one
from airbearing.analysis.campaign.spec import Campaign, parse_campaign, read_campaign

__all__ = ["Campaign", "open_client", "parse_campaign", "read_campaign", "run_campaign", "run_one"]
