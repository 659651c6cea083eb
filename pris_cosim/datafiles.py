"""Paths of the data shipped inside the package (``pris_cosim/data``).

The real measurements, the thesis netlists and the examples travel with the
package, so a clone and an installed wheel read the same files.
"""

from __future__ import annotations

from pathlib import Path

#: Root of the shipped data.
DATA: Path = Path(__file__).resolve().parent / "data"
#: Real measurements made by other people (see ``data/real/README.md``).
REAL: Path = DATA / "real"
#: The thesis's circuits as ngspice netlists.
NETLISTS: Path = DATA / "netlists"


def data_path(relative: str) -> Path:
    """Path of a shipped data file.

    Parameters
    ----------
    relative : str
        Path below ``pris_cosim/data``, for example ``"real/small_transformer_3_loads.csv"``.

    Returns
    -------
    pathlib.Path
        The file's absolute path.

    Raises
    ------
    FileNotFoundError
        When no such file is shipped (one line naming it).
    """
    p = DATA / relative
    if not p.exists():
        raise FileNotFoundError(f"{relative}: no such file in the shipped data ({DATA})")
    return p
