"""Studies, figures and tables that only read results: Dask sweeps, paper-style figures, renders.

Modules
-------
studies      alpha / lambda / noise / method sweeps on Dask, their results table
run_report   figures and tables of a rig run folder or of a sweep table
figures      paper-style figures (matplotlib), written atomically as PNG and PDF
render       software rendering of meshes for figures
tables       CSV and Markdown tables, one writer for reports, studies and benchmarks
"""
