"""Studies, figures and tables that only read results: Dask sweeps, paper-style figures, renders.

Modules
-------
studies      alpha / lambda / noise / method sweeps on Dask, their results table
run_report   figures and tables of a rig run folder (re-exports the sweep and penetration reports)
sweep        figures and tables of a sweep's results table and of the weight-step formulations
penetration  close-ups of lips and lids: plain transfer / virtual edges / exact contact, pairs in red
figures      paper-style figures (matplotlib), written atomically as PNG and PDF
render       software rendering of meshes for figures
tables       CSV and Markdown tables, one writer for reports, studies and benchmarks
"""
