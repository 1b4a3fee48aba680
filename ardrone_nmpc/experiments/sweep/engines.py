"""A sweep's cases on the one parallel executor (:mod:`ardrone_nmpc.experiments.parallel`):
this process, a pool of local worker processes, or Dask.

:func:`run_cases` flies every case with :func:`~ardrone_nmpc.experiments.sweep.cases.run_case`
and yields their :class:`~ardrone_nmpc.experiments.sweep.cases.CaseResult` s in case order;
a worker that died fails its case. :func:`iter_local` and :func:`iter_dask` are the same for
one engine. Dask workers need this package and the sweep directory at the same path (a
shared filesystem for a multi-machine cluster); configs travel with the cases, resolved.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from ardrone_nmpc.experiments.parallel import ORPHAN_EXIT, Done, open_executor
from ardrone_nmpc.experiments.record import one_line
from ardrone_nmpc.experiments.sweep.cases import CaseResult, nan_metrics, run_case
from ardrone_nmpc.experiments.sweep.status import DIVERGE_M

if TYPE_CHECKING:  # pragma: no cover
    from ardrone_nmpc.experiments.sweep.grid import Case

__all__ = ["ORPHAN_EXIT", "case_result", "iter_dask", "iter_local", "run_cases"]


def case_result(case: Case, done: Done) -> CaseResult:
    """The result of ``case`` from the executor: what it returned, or ``failed`` with the
    worker's error."""
    if done.error is None:
        return done.value
    return CaseResult(case.case_id, "failed", f"worker: {one_line(done.error)}", nan_metrics(),
                      case.case_id)


def run_cases(cases: Sequence[Case], *, out_dir: str | Path, engine: str = "local",
              jobs: int = 1, scheduler: str | None = None,
              diverge_m: float = DIVERGE_M) -> Iterator[CaseResult]:
    """Fly ``cases`` on ``engine`` with ``jobs`` workers; yield their results in case order.
    Closing the generator (or Ctrl-C while it waits) cancels the cases not started; the
    running ones finish (local pool) or are cancelled (Dask)."""
    if not cases:
        return
    out = str(Path(out_dir).resolve())  # a worker's working directory may differ
    by_id = {c.case_id: c for c in cases}
    with open_executor(engine, jobs=max(1, min(jobs, len(cases))),
                       scheduler=scheduler) as executor:
        for done in executor.map(run_case, cases, key=lambda c: c.case_id, out_dir=out,
                                 diverge_m=diverge_m):
            yield case_result(by_id[done.key], done)


def iter_local(cases: Sequence[Case], *, out_dir: str | Path, jobs: int,
               diverge_m: float = DIVERGE_M) -> Iterator[CaseResult]:
    """:func:`run_cases` on this machine (``jobs == 1``: in this process)."""
    return run_cases(cases, out_dir=out_dir, engine="local", jobs=jobs, diverge_m=diverge_m)


def iter_dask(cases: Sequence[Case], *, out_dir: str | Path, jobs: int,
              scheduler: str | None = None,
              diverge_m: float = DIVERGE_M) -> Iterator[CaseResult]:
    """:func:`run_cases` on a Dask cluster (``scheduler``, or a local one of ``jobs``)."""
    return run_cases(cases, out_dir=out_dir, engine="dask", jobs=jobs, scheduler=scheduler,
                     diverge_m=diverge_m)
