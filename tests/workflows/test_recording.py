"""Recording validation: every error names file, column and row; scales and splits."""

import os

import numpy as np
import pytest

from phs.errors import InputDataError
from phs.workflows.recording import Recording, unit_factor

GOOD = "t,pos_mm,volt_kV\n0,0,0\n0.001,1,5\n0.002,2,5\n0.003,3,5\n"


def _write(tmp_path, text, name="rec.csv"):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def test_scales_and_mapping(tmp_path):
    rec = Recording.from_csv(_write(tmp_path, GOOD), mapping={"pos_mm": "tip", "volt_kV": "U"},
                             scales={"pos_mm": ("mm", "m"), "volt_kV": ("kV", "V")})
    assert rec["tip"].tolist() == pytest.approx([0, 1e-3, 2e-3, 3e-3])
    assert rec["U"][1] == 5000.0


def test_split_by_time():
    rec = Recording.from_arrays(np.linspace(0, 1, 101), {"y": np.linspace(0, 1, 101)})
    train, valid = rec.split(0.6)
    assert (len(train), len(valid)) == (61, 41)
    assert train.t[-1] == valid.t[0] == pytest.approx(0.6)


@pytest.mark.parametrize("text, culprits", [
    ("t,y\n0,1\n0.001,x\n0.002,3\n0.003,4\n", ["row 3", "'y'", "not a number"]),
    ("t,y\n0,1\n0.001,nan\n0.002,3\n0.003,4\n", ["row 3", "'y'", "not finite"]),
    ("t,y\n0,1\n0.002,2\n0.001,3\n0.003,4\n", ["row 4", "not strictly increasing"]),
    ("t,y\n0,1\n0.001,2\n0.001,3\n0.003,4\n", ["row 4", "duplicated"]),
    ("t,y\n0,1\n0.001,2\n0.002,3\n0.0035,4\n", ["irregular sampling", "resample"]),
    ("t,y\n0,1\n", ["at least 3"]),
    ("time,y\n0,1\n0.001,2\n0.002,3\n", ["no time column 't'"]),
    ("t,y\n0,1\n0.001,\n0.002,3\n", ["row 3", "empty"]),
])
def test_invalid_csv_names_file_column_row(tmp_path, text, culprits):
    path = _write(tmp_path, text)
    before = sorted(os.listdir(tmp_path))
    with pytest.raises(InputDataError) as err:
        Recording.from_csv(path)
    msg = str(err.value)
    assert "rec.csv" in msg
    for c in culprits:
        assert c in msg, msg
    assert sorted(os.listdir(tmp_path)) == before  # nothing written


def test_irregular_sampling_resampled_only_when_asked(tmp_path):
    path = _write(tmp_path, "t,y\n0,0\n0.001,1\n0.002,2\n0.0035,3.5\n")
    rec = Recording.from_csv(path, resample=0.0005)
    assert np.allclose(np.diff(rec.t), 0.0005)
    assert rec["y"][-1] == pytest.approx(3.5)


def test_missing_column_and_bad_units(tmp_path):
    path = _write(tmp_path, GOOD)
    with pytest.raises(InputDataError, match="no column 'pos'"):
        Recording.from_csv(path, mapping={"pos": "tip"})
    with pytest.raises(InputDataError, match="different dimensions"):
        unit_factor("mm", "V")
    assert unit_factor("mA", "A") == pytest.approx(1e-3)
