"""Parallel work through joblib, the one way flockkit and its plugins run jobs on workers.

Any joblib backend runs it without a code change: the default loky processes, a Dask cluster
(``joblib.parallel_config(backend="dask")`` inside a ``distributed.Client``), or Ray
(``ray.util.joblib.register_ray()``, then ``backend="ray"``). A caller that gives no ``n_jobs``
gets the one configured with ``joblib.parallel_config`` (1 when none is), so a whole pipeline
can be sent to a cluster from outside. What goes to workers is component instances and arrays,
never names, so results do not depend on where they are computed.

    from flockkit import parallel

    squares = list(parallel.imap(pow, [(k, 2) for k in range(10)], n_jobs=2))
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator

from .errors import MissingDependencyError, ValidationError

__all__ = ["jobs", "imap", "one_thread"]


def jobs(n_jobs: int | None = None) -> int:
    """How many workers `n_jobs` means: itself when given (-1: every core of the backend), else
    the n_jobs of the active ``joblib.parallel_config`` (1 when none is set). 0 is refused."""
    if n_jobs is None:
        from joblib.parallel import get_active_backend

        _, configured = get_active_backend()
        n_jobs = 1 if configured in (None, 1) else configured
    if isinstance(n_jobs, bool) or not isinstance(n_jobs, int) or n_jobs == 0:
        raise ValidationError(f"n_jobs must be None or a non-zero integer; got {n_jobs!r}")
    return n_jobs


def imap(function: Callable, calls: Iterable[tuple], *, n_jobs: int | None = None) -> Iterator:
    """``function(*args)`` for each tuple in `calls`, in order: here when ``jobs(n_jobs)`` is 1,
    else on joblib workers, yielded as they finish where the backend can (Dask, loky) and all at
    once where it cannot (Ray). Raises MissingDependencyError, naming the module, when the workers
    cannot import what the work needs."""
    count = jobs(n_jobs)
    function = one_thread(function)
    if count == 1:
        return (function(*args) for args in calls)
    from joblib import Parallel, delayed
    from joblib.parallel import get_active_backend

    backend, _ = get_active_backend()
    calls = list(calls)
    if type(backend).__name__ not in _SAME_ENVIRONMENT:
        _probe(count, function, calls)
    lazily = getattr(backend, "supports_return_generator", False)
    runner = Parallel(n_jobs=count, return_as="generator" if lazily else "list")
    try:
        return _checked(runner(delayed(function)(*args) for args in calls))
    except (ModuleNotFoundError, ImportError) as exc:
        raise _missing(exc) from exc


class one_thread:  # noqa: N801 - used as a function, like functools.partial
    """`function` run with one BLAS and OpenMP thread: sums split over threads round differently,
    and workers get different thread counts (loky gives each cores / n_jobs), so the same job
    would give results a few ulps apart in this process and on a worker."""

    def __init__(self, function: Callable):
        self.function = getattr(function, "function", function)

    def __call__(self, *args):
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1):
            return self.function(*args)


# joblib's own backends run workers from this very environment; others (Dask, Ray) may not
_SAME_ENVIRONMENT = {"LokyBackend", "MultiprocessingBackend", "ThreadingBackend", "SequentialBackend"}


def _probe(count, function, calls) -> None:
    """Import, on the workers, every module the work will need, with a call that needs nothing
    but the standard library to arrive: a worker that lacked one would otherwise fail to even
    read its task, and some clusters (Dask) then restart it and retry for ever."""
    import importlib

    from joblib import Parallel, delayed

    modules = {"flockkit", function.function.__module__}
    for args in calls[:1]:
        modules.update(type(arg).__module__ for arg in args)
    modules = sorted(m.split(".")[0] for m in modules if m and m.split(".")[0] not in ("builtins", "numpy"))
    try:
        Parallel(n_jobs=count)(delayed(importlib.import_module)(name) for name in dict.fromkeys(modules))
    except (ModuleNotFoundError, ImportError) as exc:
        raise _missing(exc) from exc


def _checked(results):
    try:
        yield from results
    except (ModuleNotFoundError, ImportError) as exc:
        raise _missing(exc) from exc


def _missing(exc: ImportError) -> MissingDependencyError:
    name = getattr(exc, "name", None) or str(exc)
    return MissingDependencyError(
        f"a joblib worker cannot import {name!r}: install it (and flockkit's plugins) in the workers' "
        f"environment ({type(exc).__name__}: {exc})"
    )
