"""FMI 2.0 call order (:class:`CallOrder`, a part of :class:`ipcosim.fmus.fmi.FmuBase`): which call each
state allows, and the message of a refused one."""
from __future__ import annotations

import math

from ipcosim.fmus.fmi_declare import _TYPES


class CallOrder:
    """The call-order state and checks of :class:`ipcosim.fmus.fmi.FmuBase`."""

    # --- FMI 2.0 call order -------------------------------------------------------------------
    # States of FMI 2.0 co-simulation (standard, section 4.2.4): instantiated ->
    # (fmi2EnterInitializationMode) initialization -> (fmi2ExitInitializationMode) stepping ->
    # (fmi2Terminate) terminated. fmi2Reset returns to instantiated (pythonfmu creates a new
    # instance). The FMUs declare canGetAndSetFMUstate="false", so every fmi2DoStep must start
    # where the last completed one ended (the start time for the first; a discarded step may be
    # retried from the same point).
    #
    # What pythonfmu 0.7.0's wrapper lets a Python FMU return decides how a refused call is
    # reported: fmi2DoStep returns fmi2Discard when ``do_step`` returns False, and every Python
    # exception becomes fmi2Fatal; no entry point can return fmi2Error. So an out-of-order
    # fmi2DoStep is logged with status fmi2Error (naming the call, its arguments and the state),
    # returns fmi2Discard and changes nothing (the instance stays usable); a set call in a state
    # that forbids it (a fixed parameter after initialization, anything after terminate) is
    # fmi2Fatal with the same kind of message, because its only other outcome would be fmi2OK.

    #: Relative tolerance on a communication point continuing the last step.
    TIME_TOLERANCE = 1e-9

    def enter_initialization_mode(self) -> None:
        if self.fmi_state != "instantiated":
            self._fail(f"fmi2EnterInitializationMode in state {self.fmi_state}: allowed only once, after "
                       f"fmi2Instantiate (or fmi2Reset)")
        self.fmi_state = "initialization"

    def _order_initialized(self) -> None:
        """fmi2ExitInitializationMode succeeded: stepping starts at the experiment's start time."""
        self.fmi_state = "stepping"
        self._next_time = self.start_time

    def _step_order_error(self, t: float, h: float) -> str | None:
        """Why ``fmi2DoStep(t, h)`` is refused in the current state, or None (the message is built
        only for a refusal: this runs on every step)."""
        expected = self._next_time
        if (self.fmi_state == "stepping" and math.isfinite(h) and h > 0 and math.isfinite(t)
                and abs(t - expected) <= self.TIME_TOLERANCE * max(1.0, abs(expected), h)):
            return None
        call = f"fmi2DoStep(currentCommunicationPoint = {t!r}, communicationStepSize = {h!r})"
        if self.fmi_state != "stepping":
            return (f"{call} in state {self.fmi_state}: allowed only after fmi2ExitInitializationMode and "
                    f"before fmi2Terminate")
        if not (math.isfinite(h) and h > 0):
            return f"{call} in state stepping: the step size must be a positive finite number"
        return (f"{call} in state stepping: the communication point does not continue the last step, "
                f"which ended at t = {expected!r} (this FMU cannot go back or skip time)")

    def _set_order_error(self, type_: type) -> str | None:
        """Why a set call is refused in the current state, or None."""
        if self.fmi_state == "terminated":
            return f"fmi2Set{_TYPES[type_].__name__} in state terminated: no value can be set after fmi2Terminate"
        return None
