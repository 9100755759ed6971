"""Exports for analysts: Parquet, MCAP for Foxglove, CSV, fleet datasets, plots, DataFrames.

Every export reads through the one columnar read path (:mod:`fleetlog.storage.columnar`)
into one table of entries (:mod:`fleetlog.export.entries`), streams, and writes its output
whole or not at all (:mod:`fleetlog.storage.outputs`). ``docs/export.md`` describes the
formats for their users.
"""

from fleetlog.export.csvout import write_csv_rows, write_csv_table
from fleetlog.export.dataset import DatasetResult, export_dataset
from fleetlog.export.entries import COLUMNS, Select, Tally
from fleetlog.export.frames import open_frame
from fleetlog.export.parquet import write_parquet
from fleetlog.export.plot import PlotResult, plot_format
from fleetlog.export.plot import plot as plot_logs
from fleetlog.export.sources import Resolved, Source, resolve
from fleetlog.export.tomcap import McapResult, export_mcap

__all__ = [
    "COLUMNS",
    "DatasetResult",
    "McapResult",
    "PlotResult",
    "Resolved",
    "Select",
    "Source",
    "Tally",
    "export_dataset",
    "export_mcap",
    "open_frame",
    "plot_format",
    "plot_logs",
    "resolve",
    "write_csv_rows",
    "write_csv_table",
    "write_parquet",
]
