"""The project's error types.

Every error raised on bad input is a :class:`PHSError`; its message names the
culprit (component, port, parameter, state, file, column or row).  Errors that
collect several problems keep them in ``problems`` and list them all.
"""

from __future__ import annotations


class PHSError(Exception):
    """Base class of every error the project raises on purpose.

    Parameters
    ----------
    message : str
        What is wrong and where.
    problems : sequence of str, optional
        Individual problems when several were collected; they are appended to
        the message, one per line.

    Examples
    --------
    >>> err = PHSError("model 'rc' is invalid", problems=["J not skew", "R not PSD"])
    >>> print(err)
    model 'rc' is invalid:
      - J not skew
      - R not PSD
    """

    def __init__(self, message: str, problems: list[str] | tuple[str, ...] = ()):
        self.problems = tuple(problems)
        text = message
        if self.problems:
            text += ":\n" + "\n".join(f"  - {p}" for p in self.problems)
        super().__init__(text)


class ModelError(PHSError, ValueError):
    """A model (component, system, parameter) is malformed.

    Examples
    --------
    >>> issubclass(ModelError, PHSError) and issubclass(ModelError, ValueError)
    True
    """


class InterconnectionError(ModelError):
    """A connection is unrealizable: unconnected port, dependent storages, unknown name.

    Examples
    --------
    >>> from phs import interconnect, parallel
    >>> from components import Capacitor
    >>> try:
    ...     interconnect("x", [Capacitor("C1"), Capacitor("C2")], [parallel("C1", "C2")])
    ... except InterconnectionError as err:
    ...     print("C1.Q" in str(err) and "C2.Q" in str(err))
    True
    """


class ParameterError(ModelError, KeyError):
    """A parameter is unknown, has no value, or is outside its declared range.

    Examples
    --------
    >>> from systems.examples import rc_circuit
    >>> try:
    ...     rc_circuit().with_params({"nope": 1.0})
    ... except ParameterError as err:
    ...     print("nope" in str(err))
    True
    """

    def __str__(self) -> str:  # KeyError would quote the message
        return Exception.__str__(self)


class ParameterRangeWarning(UserWarning):
    """A parameter value outside the parameter's declared range (accepted: ranges bound sampling and fits,
    not physics; a value of the wrong sign is refused with :class:`ParameterError` instead).

    Examples
    --------
    >>> import warnings
    >>> from systems.examples import rc_circuit
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     _ = rc_circuit().with_params({"R.R": 1e9})
    >>> caught[0].category is ParameterRangeWarning and "R.R" in str(caught[0].message)
    True
    """


class InputHoldWarning(UserWarning):
    """A recorded input whose samples look held between samples (isolated jumps between flat stretches, as a DAC's
    command: :func:`phs.kinks.held_between_samples`) is read as a continuous signal because nothing declared how it
    behaves between samples.  Declaring it (``holds=``, ``--hold``, a header ``U [V] {zoh}``) silences it.

    Examples
    --------
    >>> issubclass(InputHoldWarning, UserWarning)
    True
    """


class UnitError(ModelError):
    """Declared units are inconsistent (an energy term that is not in joules).

    Examples
    --------
    >>> from phs.units import parse_unit
    >>> try:
    ...     parse_unit("furlong")
    ... except UnitError as err:
    ...     print(err)
    unknown unit 'furlong' in 'furlong'
    """


class DomainError(PHSError, ArithmeticError):
    """A state left the model's validity domain (for example an arcsin argument above 1).

    Examples
    --------
    >>> issubclass(DomainError, PHSError)
    True
    """


class SimulationError(PHSError, RuntimeError):
    """The integrator failed, or the solution became non-finite.

    Examples
    --------
    >>> str(SimulationError("the integrator failed at t=0.5"))
    'the integrator failed at t=0.5'
    """


class InputDataError(PHSError, ValueError):
    """An input signal, CSV file or command-line argument is malformed.

    Examples
    --------
    >>> from phs.signals import parse_expression
    >>> try:
    ...     parse_expression("sin(x)")
    ... except InputDataError as err:
    ...     print("'x'" in str(err))
    True
    """


class EquilibriumError(PHSError, RuntimeError):
    """No equilibrium could be found for the requested input or target.

    Examples
    --------
    >>> issubclass(EquilibriumError, PHSError)
    True
    """
