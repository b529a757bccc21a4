"""Loading the dual-arm scanning station of the ``dualarm`` paper and the paper's published
numbers.

:func:`load_scenario` reads ``data/dualarm/scenario.toml`` (cameras, markers of Table A1,
transforms of Table A2, noise and the experiments' geometry, each entry with its provenance) into
the validated :class:`~calstudy.papers.dualarm.schema.Scenario`; :func:`load_published` reads
``data/dualarm/published.toml`` (the results of Section 4 and Tables 1-3). A missing file or key
is reported as in every paper.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from calstudy.core.schema import load_paper_file
from calstudy.papers.dualarm.schema import PublishedFile, Scenario

PAPER = "dualarm"
#: the two standard spheres of Section 4.1
SPHERES = ("A", "B")


def load_scenario(
    path: str | Path | None = None, overrides: Mapping[str, object] | None = None
) -> Scenario:
    """The station of ``data/dualarm/scenario.toml`` (or ``path``).

    Parameters
    ----------
    path : str or Path, optional
        A scenario file of your own (same keys); default the paper's.
    overrides : mapping of str to object, optional
        Dotted keys of the file (``{"detection.sigma_px": 0.05}``) and the values to read in
        their place; each is validated as if the file held it (its type, physical bound and
        ledger range).

    Returns
    -------
    Scenario
        The validated, frozen station (lengths mm, derived angles rad).

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    CalibrationError
        If it is not valid TOML, if an override names no input of the file, or if it breaks
        :class:`~calstudy.papers.dualarm.schema.Scenario`: a missing or unknown key, a value out
        of range (``loss_rate = 1.5``, ``points_per_scan = -500``), markers without a group; the
        message names the file, the key, the value and the allowed range.
    """
    return load_paper_file(
        PAPER, "scenario.toml", Scenario, "dualarm scenario", path, overrides
    )


def load_published(path: str | Path | None = None) -> PublishedFile:
    """The paper's numbers, ``data/dualarm/published.toml`` (or ``path``), mm: ``icp.rows``
    (Section 4.1: ``[arm, sphere, before, after]`` mean centre errors of the multi-view fits),
    ``table1.rows`` (``[group, dx, dy, dz]``, group 0: all groups), ``table2.rows`` (``[group,
    pose 1, pose 2, pose 3]``) and ``table2.overall`` (the overall mean Euclidean error the text
    gives), ``table3.methods`` and ``table3.rows`` (``[dx, dy, dz, euclid]`` per method).

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    CalibrationError
        If it is not valid TOML or breaks :class:`~calstudy.papers.dualarm.schema.PublishedFile`
        (a missing or unknown key, a negative error, a group or an arm-sphere pair given twice,
        methods and rows that differ in number).
    """
    return load_paper_file(
        PAPER, "published.toml", PublishedFile, "dualarm published results", path
    )


__all__ = ["SPHERES", "load_published", "load_scenario"]
