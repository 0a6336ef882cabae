"""Monte-Carlo fault campaigns (``ehpss-hil campaign``): a campaign file of distributions →
sampled scenarios → every mode simulated per run, on local processes or a Dask cluster → one
Parquet row per run, a summary per fault class, worst cases, coverage maps (docs/campaigns.md).

Modules, from the bottom up: :mod:`.spec` (the campaign file), :mod:`.sampling` (run index →
scenario), :mod:`.scenario_file` (a scenario back to YAML), :mod:`.runs` (one run → one row),
:mod:`.journal` (finished rows, kill-safe), :mod:`.executors` (local pool), :mod:`.cluster` (Dask:
a scheduler or a LocalCluster, lost workers, retries), :mod:`.progress`,
:mod:`.table` (Parquet/CSV), :mod:`.summary` (fault classes, worst cases, summary.md),
:mod:`.figures` (coverage maps, distributions).
"""
