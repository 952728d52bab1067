"""Progress of long jobs: one reporter for batched prediction (:func:`layerstack_jax.predict`),
batch, multi-start and cube fits and the needle design (:mod:`fitting`).

A job counts what it has done (spectra, fits, starts, pixels, refinement steps) and calls
``update(done)`` — or ``update(done, note)`` with a short text such as the current merit —
after each piece. What the user sees is chosen by the job's ``progress`` argument:

* a callable ``f(done, total)``: called as is (logging, a GUI, a test);
* ``True``: a tqdm bar (``tqdm.auto``: a widget in notebooks, text on stderr elsewhere);
* ``False``: nothing;
* ``None``: a bar when the job says it is long enough to deserve one (``auto``), else nothing.
"""

from __future__ import annotations

from typing import Callable, Optional

__all__ = ["reporter"]


def reporter(progress, total: int, *, desc: str, unit: str, initial: int = 0,
             auto: bool = False) -> Optional[Callable[..., None]]:
    """``update(done, note="")`` reporting ``done`` of ``total`` ``unit``s of the job ``desc``
    as ``progress`` asks (module docstring), or None when nothing is to be reported.

    ``initial``: units already done before this run (a resumed job); ``auto``: whether
    ``progress=None`` shows a bar."""
    if progress is False or (progress is None and not auto):
        return None
    if callable(progress):
        return lambda done, note="": progress(done, total)
    from tqdm.auto import tqdm

    bar = tqdm(total=total, initial=initial, unit=unit, desc=desc, smoothing=0.1)

    def update(done: int, note: str = "") -> None:
        if note:
            bar.set_postfix_str(note, refresh=False)
        bar.update(done - bar.n)
        if done >= total:
            bar.close()

    return update
