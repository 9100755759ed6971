"""fleetlog: the MOOS logger and player rebuilt on Eclipse Zenoh for fleets of vehicles.

``fleetlog.open(path)`` reads logs, a Parquet export or a fleet dataset as a polars DataFrame
(:func:`fleetlog.export.frames.open_frame`); the rest is the ``fleetlog`` command.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import polars as pl

__version__ = "0.1.0"
__all__ = ["__version__", "open"]


def open(
    source: str | os.PathLike[str] | Sequence[str | os.PathLike[str]], **options: Any
) -> pl.DataFrame:
    """Read logs, a Parquet export or a fleet dataset as one polars DataFrame.

    Example::

        import fleetlog
        nav = fleetlog.open("archive/", variables=["NAV_X", "NAV_Y"])
        nav.filter(vehicle="alpha").to_pandas()   # pandas, if pandas and pyarrow are there

    See :func:`fleetlog.export.frames.open_frame` for the options and columns.
    """
    from fleetlog.export.frames import open_frame

    return open_frame(source, **options)
