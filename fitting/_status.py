"""Status of a fit, in the library's words: codes shared by :func:`~fitting.fit`,
:func:`~fitting.fit_batch` and their results (``result_code``), and their messages."""

from __future__ import annotations

__all__ = ["CONVERGED", "MAX_STEPS", "NONFINITE", "FAILED", "INVALID_DATA", "ABANDONED", "STATUS", "result_message"]

#: Status codes of a fit (``FitResult.result_code``, ``BatchResult.result_code``).
CONVERGED, MAX_STEPS, NONFINITE, FAILED, INVALID_DATA, ABANDONED = 0, 1, 2, 3, 4, 5
STATUS = {
    CONVERGED: "converged: the solver met its tolerance",
    MAX_STEPS: "not converged: the step limit (max_steps) was reached before the tolerance was met",
    NONFINITE: "failed: the model, the residuals or the Jacobian became NaN or infinite",
    FAILED: "failed: the solver could not make progress (singular or diverging linearised problem)",
    INVALID_DATA: "not fitted: invalid data (see the batch's invalid_data)",
    ABANDONED: ("not converged: a multi-start start given up — after the give-up step count its cost was still far "
                "above that of the best start converged before it (fitting._multistart.give_up_rule)"),
}


def result_message(code: int) -> str:
    """The library's message for a status code (:data:`STATUS`)."""
    return STATUS.get(int(code), f"unknown status {int(code)}")
