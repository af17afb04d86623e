"""`velogauss sweep GRID.toml`: studies (scenes × ablations × seeds × settings) on Ray.

`grid` parses the grid file into points, `runner` trains each point in its own Ray task and
resumes what a killed sweep left, `report` writes results.csv, results.md and the plots.
Ray is the optional extra `velogauss[sweep]`; nothing here imports it until a sweep runs.
"""

from velogauss.sweep.grid import Point, Sweep, load_grid

__all__ = ["Point", "Sweep", "load_grid"]
