"""Reading a recording's CSV file: numpy's one-pass reading of a file of finite numbers (phs.workflows.inputs.
_fast_rows) against the cell-by-cell reading every other file gets, and the errors of both."""

from __future__ import annotations

import numpy as np
import pytest

from phs.errors import InputDataError
from phs.workflows import inputs as inputs_module
from phs.workflows.inputs import _read_rows, _Table, read_input_csv
from phs.workflows.recording import Recording
from systems.examples import rc_circuit

BODY = ("t [s],U [V],v_C\r\n"
        "0,1.5e-3,-2\r\n"
        " 0.001 ,\"2.25\",1E2\r\n"
        "0.002,-0.0,3.0000000000000004\r\n"
        "0.003,7,0.1\r\n")


def _write(tmp_path, text, name="r.csv"):
    p = tmp_path / name
    p.write_bytes(text.encode())
    return str(p)


def _slow(monkeypatch):
    monkeypatch.setattr(inputs_module, "_fast_rows", lambda path: None)


def test_the_fast_reading_gives_the_cell_by_cell_numbers_bitwise(tmp_path, monkeypatch):
    rng = np.random.default_rng(0)
    data = np.column_stack([np.arange(500) * 1e-3, rng.normal(size=500) * 10.0 ** rng.integers(-12, 12, 500), rng.normal(size=500)])
    lines = ["t,U,v_C"] + [f"{float(a)!r},{float(b)!r},{c:.17g}" for a, b, c in data]
    for text in (BODY, "\n".join(lines), "\n".join(lines) + "\n"):
        p = _write(tmp_path, text)
        header, rows = _read_rows(p)
        assert isinstance(rows, _Table)  # these files are all numbers: read in one pass
        fast = Recording.from_csv(p)
        t_fast, u_fast = read_input_csv(p, rc_circuit())
        with monkeypatch.context() as m:
            _slow(m)
            slow = Recording.from_csv(p)
            t_slow, u_slow = read_input_csv(p, rc_circuit())
        assert np.array_equal(fast.t, slow.t) and fast.names == slow.names
        assert all(np.array_equal(fast[k], slow[k]) for k in fast.names)
        assert np.array_equal(t_fast, t_slow) and u_fast["U"].values == u_slow["U"].values


@pytest.mark.parametrize("text, message", [
    ("t,U\n0,1\n\n0.001,2\n0.001,3\n", "row 5"),           # a blank line: the rows after it keep their numbers
    ("t,U\n0,1\n0.001,nan\n0.002,3\n", "row 3, column 'U': value 'nan' is not finite"),
    ("t,U\n0,1\n0.001,1_0\n0.002,a\n", "row 4, column 'U': 'a' is not a number"),
    ("t,U\n0,1\n0.001,\n0.002,3\n", "row 3, column 'U': is empty"),
    ("t,U\n0,1\n0.001,2,3\n", "row 3 has 3 cells but the header has 2 columns"),
    ("t,U,U\n0,1,1\n0.001,2,2\n", "column 'U' appears twice"),
    ("t,U\n0,1\n0.002,2\n0.002,3\n", "row 4"),              # read in one pass: the row still named
])
def test_errors_name_the_row_and_column_as_before(tmp_path, monkeypatch, text, message):
    p = _write(tmp_path, text)
    with pytest.raises(InputDataError, match=message.replace("(", r"\(")) as fast:
        Recording.from_csv(p)
    _slow(monkeypatch)
    with pytest.raises(InputDataError) as slow:
        Recording.from_csv(p)
    assert str(fast.value) == str(slow.value)
