"""Measurements of a fixed sphere for the sphere hand-eye (hybrid Eq. 6-14): the CSV a user
hands in (one row per measurement), read with its units checked, and written back.

The schema is in the README ("Your own measurements: hand-eye CSV schema").
"""


from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.core.userfile import (
    ANGLE_UNITS,
    LENGTH_UNITS,
    check_ids,
    parse_number,
    read_csv_table,
    require_columns,
)

SPHERE_CSV_COLUMNS = ("id", "group", "x", "y", "z", "a", "b", "c", "sx", "sy", "sz")
SPHERE_CSV_GROUPS = ("translation", "rotation")


@dataclass
class SphereMeasurements:
    """Fixed-sphere hand-eye measurements: flange poses and sphere centres, split by group.

    Attributes
    ----------
    ids : (N,) int array
    group : (N,) str array, ``"translation"`` or ``"rotation"``
    flange2base : (N, 4, 4) array, mm
    centres : (N, 3) array, sphere centre in the sensor frame, mm
    """

    ids: np.ndarray
    group: np.ndarray
    flange2base: np.ndarray
    centres: np.ndarray

    def select(self, group: str) -> tuple[np.ndarray, np.ndarray]:
        """Flange poses and centres of one group.

        Parameters
        ----------
        group : {"translation", "rotation"}
            The group of rows.

        Returns
        -------
        flange2base : numpy.ndarray, shape (n, 4, 4)
            The group's flange poses, mm.
        centres : numpy.ndarray, shape (n, 3)
            The group's measured centres in the sensor frame, mm.

        Raises
        ------
        None
        """
        mask = self.group == group
        return self.flange2base[mask], self.centres[mask]

    def to_frame(self):
        """The measurements as a DataFrame in the CSV schema.

        Returns
        -------
        pandas.DataFrame
            Columns ``id, group, x, y, z`` (mm), ``a, b, c`` (KUKA angles, deg),
            ``sx, sy, sz`` (mm).

        Raises
        ------
        None
        """
        import pandas as pd

        abc = geo.matrix_to_euler_zyx(self.flange2base[:, :3, :3])
        xyz = self.flange2base[:, :3, 3]
        return pd.DataFrame(
            {
                "id": self.ids,
                "group": self.group,
                "x": xyz[:, 0],
                "y": xyz[:, 1],
                "z": xyz[:, 2],
                "a": abc[:, 0],
                "b": abc[:, 1],
                "c": abc[:, 2],
                "sx": self.centres[:, 0],
                "sy": self.centres[:, 1],
                "sz": self.centres[:, 2],
            }
        )


#: the angle unit suffixes a column name may declare, in degrees per unit (the schema's unit;
#: lengths are in mm, :data:`calstudy.core.userfile.LENGTH_UNITS`)
_DEGREES_PER = {unit: rad / ANGLE_UNITS["deg"] for unit, rad in ANGLE_UNITS.items()}
#: positions whose largest magnitude is below this (mm) are suspected to be metres when the
#: other group of lengths reaches :data:`_MM_TYPICAL`
_METRE_SUSPECT = 10.0
_MM_TYPICAL = 100.0


def _sphere_columns(path, header: list[str]) -> tuple[dict[str, str], dict[str, float]]:
    """Map each schema column to the file's column (bare, or with a declared unit suffix) and
    give each group's factor to mm / deg; ``nan`` factor means the unit is not declared."""
    mapping, factors = {}, {}
    groups = {"xyz": ("x", "y", "z"), "abc": ("a", "b", "c"), "sxyz": ("sx", "sy", "sz")}
    for group, cols in groups.items():
        units = _DEGREES_PER if group == "abc" else LENGTH_UNITS
        found = set()
        for col in cols:
            names = [col] + [f"{col}_{u}" for u in units]
            present = [n for n in names if n in header]
            if len(present) > 1:
                raise CalibrationError(
                    f"{path}: column {col!r} is given twice ({', '.join(present)})"
                )
            if not present:
                raise CalibrationError(
                    f"{path}: missing column {col!r} (or {col}_<unit> with unit "
                    f"{' or '.join(units)}); the header has {', '.join(header)}"
                )
            mapping[col] = present[0]
            found.add(present[0][len(col) + 1 :] or None)
        if len(found) > 1:
            bare = [c for c in cols if mapping[c] == c]
            raise CalibrationError(
                f"{path}: missing column(s) {', '.join(c + '_<unit>' for c in bare)}: columns "
                f"{', '.join(mapping[c] for c in cols)} mix declared and undeclared units; give "
                "all three the same suffix"
            )
        unit = found.pop()
        factors[group] = float("nan") if unit is None else units[unit]
    require_columns(path, header, ["id", "group"])
    mapping |= {"id": "id", "group": "group"}
    return mapping, factors


def _check_units(path, values: np.ndarray, factors: dict[str, float]) -> None:
    """Refuse undeclared units that look like radians or metres (the suspicion stated)."""
    abc, xyz, sxyz = values[:, 4:7], values[:, 1:4], values[:, 7:10]
    if np.isnan(factors["abc"]):
        largest = float(np.abs(abc).max())
        if 0.0 < largest <= np.pi:
            raise CalibrationError(
                f"{path}: every value of columns a, b, c lies within +-pi (largest |value| "
                f"{largest:.4g}): they look like radians, but the schema expects degrees; "
                "convert them, or declare the unit by naming the columns a_rad, b_rad, c_rad"
            )
    big = {"xyz": float(np.abs(xyz).max()), "sxyz": float(np.abs(sxyz).max())}
    what = {"xyz": "flange positions x, y, z", "sxyz": "sphere centres sx, sy, sz"}
    declare = {"xyz": "x_m, y_m, z_m", "sxyz": "sx_m, sy_m, sz_m"}
    for group, other in (("xyz", "sxyz"), ("sxyz", "xyz")):
        if not np.isnan(factors[group]) or big[group] >= _METRE_SUSPECT:
            continue
        if big[other] >= _MM_TYPICAL or big[other] < _METRE_SUSPECT:
            raise CalibrationError(
                f"{path}: the {what[group]} are all below {_METRE_SUSPECT:g} (largest |value| "
                f"{big[group]:.4g}) while the {what[other]} reach {big[other]:.4g}: they look "
                "like metres, but the schema expects mm; convert them, or declare the unit by "
                f"naming the columns {declare[group]}"
            )


def _cells(path, header: list[str], rows, mapping: dict[str, str]):
    """The numeric columns ``(N, 10)`` (id, x, y, z, a, b, c, sx, sy, sz as written) and the
    groups ``(N,)``; the first bad cell, row by row in schema order, is named."""
    index = {col: header.index(mapping[col]) for col in SPHERE_CSV_COLUMNS}
    numeric = [c for c in SPHERE_CSV_COLUMNS if c != "group"]
    values = np.empty((len(rows), len(numeric)))
    for i, (line, cells) in enumerate(rows):
        for col in SPHERE_CSV_COLUMNS:
            text = cells[index[col]]
            if col == "group":
                if text not in SPHERE_CSV_GROUPS:
                    raise CalibrationError(
                        f"{path}: row {line}, column 'group': {text!r} is not one of "
                        f"{' or '.join(repr(g) for g in SPHERE_CSV_GROUPS)}"
                    )
            else:
                values[i, numeric.index(col)] = parse_number(path, line, col, text)
    groups = np.array([cells[index["group"]] for _, cells in rows])
    return values, groups


def read_sphere_measurements(path) -> SphereMeasurements:
    """Read a user's fixed-sphere measurements from CSV (schema in the README).

    One row per measurement with columns ``id, group, x, y, z, a, b, c, sx, sy, sz``: ``group`` is
    ``translation`` (flange orientation unchanged) or ``rotation``; ``x, y, z`` (mm) and
    ``a, b, c`` (deg, ``R = Rz(a) Ry(b) Rx(c)``, the KUKA convention) are the flange pose read
    from the robot controller; ``sx, sy, sz`` (mm) the sphere centre measured in the sensor frame.
    A column may declare its unit by a suffix (``x_mm`` or ``x_m``, ``a_deg`` or ``a_rad``, the
    same for the three columns of a group); declared units are converted. Spreadsheet files are
    accepted: a UTF-8 byte-order mark, ``;`` as the separator, ``#`` comment lines.

    Checks, each naming the file and the row and column where it applies: every column present;
    every cell a finite number (a decimal comma ``12,5`` is named as such), ``group`` one of
    ``translation, rotation`` (each with rows), ids distinct integers; and, where units are not
    declared, their plausibility: angles that all lie within +-pi look like radians, positions
    all below 10 while the other lengths reach 100 or more look like metres (both refused with
    the suspicion stated).

    Parameters
    ----------
    path : str or pathlib.Path
        The CSV file.

    Returns
    -------
    SphereMeasurements
        Ids, groups, flange poses (N, 4, 4) in mm and the measured centres (N, 3) in mm, units
        converted.

    Raises
    ------
    FileNotFoundError
        If ``path`` is not a file.
    CalibrationError
        On any of the checks above.
    """
    header, rows = read_csv_table(path, "fixed-sphere measurement file")
    mapping, factors = _sphere_columns(path, header)
    values, groups = _cells(path, header, rows, mapping)
    absent = [g for g in ("translation", "rotation") if not np.any(groups == g)]
    if absent:
        raise CalibrationError(
            f"{path}: no rows of group {absent[0]!r}; the calibration needs translation rows "
            "(one orientation) and rotation rows"
        )
    _check_units(path, values, factors)
    values[:, 1:4] *= np.nan_to_num(factors["xyz"], nan=1.0)
    values[:, 4:7] *= np.nan_to_num(factors["abc"], nan=1.0)
    values[:, 7:10] *= np.nan_to_num(factors["sxyz"], nan=1.0)
    ids = check_ids(path, values[:, 0], [n for n, _ in rows])
    rot = geo.euler_zyx_to_matrix(values[:, 4], values[:, 5], values[:, 6])
    return SphereMeasurements(
        ids=ids,
        group=groups,
        flange2base=geo.make_transform(rot, values[:, 1:4]),
        centres=values[:, 7:10],
    )


def write_sphere_measurements(measurements: SphereMeasurements, path) -> None:
    """Write measurements in the CSV schema of :func:`read_sphere_measurements` (full precision).

    Parameters
    ----------
    measurements : SphereMeasurements
        The measurements (mm, flange angles in deg).
    path : str or pathlib.Path
        The file to write.

    Returns
    -------
    None

    Raises
    ------
    OSError
        If the file cannot be written.
    """
    measurements.to_frame().to_csv(path, index=False, float_format="%.10f")
