"""``phs list`` and the bundled example recordings: one line per system and recording, the files
regenerate from their declarations, and a fit recovers the parameters they were made with."""

from __future__ import annotations

import io
import tomllib
from pathlib import Path

import numpy as np
import pytest

import systems
from phs.errors import InputDataError
from phs.workflows.bundled import RECORDINGS, listing, make_recording, recording_path
from phs.workflows.cli import main
from phs.workflows.recording import Recording

ROOT = Path(__file__).resolve().parents[2]


def test_listing_has_one_line_per_system_and_recording():
    lines = listing().splitlines()
    for name in systems.MODELS:
        assert sum(line.split()[0] == name for line in lines[1:]) == 1, name
    for rec in RECORDINGS:
        assert any(line.split()[0] == rec.name for line in lines), rec.name
    assert len(lines) == len(systems.MODELS) + len(RECORDINGS) + 2


def test_phs_list_prints_the_listing_and_a_path(capsys):
    assert main(["list"]) == 0
    assert capsys.readouterr().out.strip() == listing()
    assert main(["list", "--path", "msd_two_tone"]) == 0
    assert Path(capsys.readouterr().out.strip()).is_file()


def test_phs_list_unknown_recording_exits_2_naming_it(capsys):
    assert main(["list", "--path", "nope"]) == 2
    err = capsys.readouterr().err
    assert "'nope'" in err and "msd_two_tone" in err


@pytest.mark.parametrize("rec", RECORDINGS, ids=lambda r: r.name)
def test_bundled_file_is_what_its_declaration_makes(rec):
    made = np.loadtxt(io.StringIO(make_recording(rec)), delimiter=",", skiprows=1)
    shipped = np.loadtxt(recording_path(rec.name), delimiter=",", skiprows=1)
    assert 200 <= len(shipped) <= 1000
    np.testing.assert_allclose(shipped, made, rtol=1e-6, atol=1e-12)


def test_bundled_files_are_package_data():
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["systems"]
    assert "data/*.csv" in data
    assert Path(recording_path(RECORDINGS[0].name)).parent == ROOT / "systems" / "data"


@pytest.mark.parametrize("rec", RECORDINGS, ids=lambda r: r.name)
def test_a_fit_recovers_the_parameters_the_recording_was_made_with(rec):
    from phs.workflows.identify import identify
    from phs.workflows.loader import load_model

    system = load_model(rec.model, {})
    fit = identify(system, Recording.from_csv(recording_path(rec.name)), list(rec.free), progress=False)
    for name in rec.free:
        value, err = fit.values[name], fit.std_errors[name]
        assert abs(value - rec.params[name]) < 4 * err + 1e-3 * abs(rec.params[name]), (name, value, err)


def test_recording_path_refuses_unknown_names():
    with pytest.raises(InputDataError, match="'x'"):
        recording_path("x")


def test_fit_reads_headers_with_units(tmp_path, capsys):
    """A CSV with ``name [unit]`` headers (as ``phs simulate --out`` writes) is read by ``phs fit``."""
    path = recording_path("msd_two_tone")
    assert Path(path).read_text().startswith("t [s],F [N],position [m]")
    assert main(["fit", "systems:mass_spring_damper", path, "--free", "k.K", "--quiet", "--max-iter", "5"]) == 0
    assert "outputs position" in capsys.readouterr().out
