"""Progress bars (tqdm) behind the ``progress(done, total, stage)`` callbacks that components
declaring ``Capabilities(progress=True)`` call."""

from __future__ import annotations

import contextlib


@contextlib.contextmanager
def progress_bar(enabled: bool, unit: str = "it"):
    """A ``progress(done, total, stage)`` callback drawing one tqdm bar per stage (None when not
    `enabled`), closed when the stage's count reaches its total (a stage reported again later gets
    a new bar); every bar is closed on leaving. Components report (0, total) as a stage starts."""
    if not enabled:
        yield None
        return
    from tqdm.auto import tqdm

    current = {"stage": None, "bar": None}

    def report(done: int, total: int, stage: str) -> None:
        bar = current["bar"]
        if bar is None or stage != current["stage"]:
            if bar is not None:
                bar.close()
            bar = current["bar"] = tqdm(total=total, desc=stage, unit=unit)
            current["stage"] = stage
        bar.total = total
        bar.update(done - bar.n)
        if done >= total:  # closed when its work is done, so that its time is the stage's own
            bar.close()
            current["bar"] = None

    try:
        yield report
    finally:
        if current["bar"] is not None:
            current["bar"].close()
