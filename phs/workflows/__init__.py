"""Workflows that run models: loading models by name, reading input recordings, the ``phs`` command line.

This part of :mod:`phs` may import :mod:`codegen` (it does so only when a model
is actually run), while the core never imports the workflows.
"""

from phs.workflows.inputs import input_signals, parse_assignments, read_input_csv
from phs.workflows.loader import load_model

__all__ = ["load_model", "read_input_csv", "parse_assignments", "input_signals"]
