"""Exit codes: the ``--help`` text, and a run's verdict turned into the command's exit status."""

from __future__ import annotations

import sys

EXIT_CODES = """exit codes:
  0    done (also a "warning" verdict: calibrated model written, reason on stderr)
  2    bad input or usage (one line "vision-calib: error: ..." on stderr)
  3    outputs written but the result is not good (failed fit, gross input error): no calibrated model
  130  interrupted (Ctrl-C); results already written are kept"""


#: exit code when the outputs were written but the result is not good (not converged, not finite)
EXIT_NOT_CONVERGED = 3


def status(verdict: dict) -> int:
    """0 for a good result, and for a "warning" verdict (outputs and calibrated model written; the model does
    not explain the data: the reason on stderr); 3 (outputs kept, no calibrated model) otherwise."""
    if verdict["ok"]:
        return 0
    if verdict.get("status") == "warning":
        print(f"vision-calib: warning: {verdict.get('message')}", file=sys.stderr)
        return 0
    why = verdict.get("message") or "the identification did not converge"
    print(f"vision-calib: error: the result is not good ({why}); outputs written without a calibrated model",
          file=sys.stderr)
    return EXIT_NOT_CONVERGED
