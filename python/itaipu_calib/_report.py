"""The report of a fit as Python gives it: the command line's ``report.json`` as a dict, which
called gives the same report as text (``result.report()``, what ``itaipu-calib fit`` prints)."""

from typing import Any, Dict


class Report(dict):  # type: ignore[type-arg]
    """``report.json`` as a dict; ``report()`` is the report as text."""

    def __init__(self, data: Dict[str, Any], text: str) -> None:
        super().__init__(data)
        self._text = text

    def __call__(self) -> str:
        """The report as text: per stage the fit statistics (n, free parameters, chi-square,
        reduced chi-square, AIC, BIC), each parameter's value, standard error, relative error
        and flag (determined / weak / not determined), the correlations, then J per event."""
        return self._text
