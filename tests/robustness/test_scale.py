"""Scale-out through joblib: the same bytes on loky, a Dask LocalCluster, separate `dask worker`
processes and Ray; joblib's configured n_jobs honoured; workers that lack flockkit named, fast.

These need the `scale` extra (dask, distributed, ray); without it they are skipped, saying so."""

import os
import shutil
import socket
import subprocess

import joblib
import pytest

import flockkit

from .harness import cli_outcome, outcome

distributed = pytest.importorskip(
    "distributed", reason="the Dask checks need the scale extra: pip install 'flockkit[scale]'"
)


@pytest.fixture(scope="module")
def work():
    """A recording, its graph and a solution made here, one worker (the reference bytes)."""
    recording = flockkit.simulate(n_agents=6, steps=200, seed=3)
    problem = flockkit.Problem(n_agents=6, duration=2.0, constraints=[
        flockkit.PointConstraint(agent=0, time=1.0, position=[0.0, 0.0], velocity=[1.0, 0.0]),
    ])  # fmt: skip
    return recording, problem, _results(recording, problem, n_jobs=1)


def _results(recording, problem, n_jobs=None):
    graph = flockkit.build_graph(recording, seed=0, n_jobs=n_jobs)
    solution = flockkit.solve(problem, iterations=10, chains=2, seed=1, n_jobs=n_jobs)
    return graph, [m.positions.tobytes() for m in solution.motions]


def _same(found, reference):
    assert found[0] == reference[0] and found[1] == reference[1]


def test_loky_gives_the_same_bytes(work):
    recording, problem, reference = work
    _same(_results(recording, problem, n_jobs=2), reference)


def test_joblibs_configured_n_jobs_is_honoured_when_none_is_given():
    with joblib.parallel_config(backend="threading", n_jobs=2):
        assert flockkit.parallel.jobs() == 2 and flockkit.parallel.jobs(1) == 1
    assert flockkit.parallel.jobs() == 1


def test_a_dask_local_cluster_gives_the_same_bytes(work):
    recording, problem, reference = work
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, dashboard_address=None) as cluster:
        with distributed.Client(cluster), joblib.parallel_config(backend="dask", n_jobs=-1):
            _same(_results(recording, problem), reference)  # no n_jobs: the cluster's, from the config


def _dask(*args, env=None):
    return subprocess.Popen([shutil.which("dask") or "dask", *args], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, env=env)  # fmt: skip


def _free_port() -> int:
    """A port no one listens on now (the system's pick). A port chosen by the clock was 8787
    (dask's default dashboard port) in one CI run, and no scheduler answered there within 30 s."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@pytest.fixture
def scheduler():
    port = _free_port()
    process = _dask("scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard")
    workers = []
    yield f"tcp://127.0.0.1:{port}", workers
    for worker in workers:
        worker.terminate()
        worker.wait(30)
    process.terminate()
    process.wait(30)


def _start_workers(scheduler, env=None):
    address, workers = scheduler
    workers.append(_dask("worker", address, "--nworkers", "2", "--nthreads", "1", "--no-dashboard", env=env))
    client = distributed.Client(address, timeout=30)
    client.wait_for_workers(2, timeout=60)
    return client


def test_separate_dask_worker_processes_give_the_same_bytes(work, scheduler):
    recording, problem, reference = work
    with _start_workers(scheduler), joblib.parallel_config(backend="dask", n_jobs=-1):
        _same(_results(recording, problem), reference)


def test_workers_that_cannot_import_flockkit_are_named_not_waited_for(work, scheduler, tmp_path):
    blocker = tmp_path / "sitecustomize.py"  # a worker environment without flockkit
    blocker.write_text(
        "import sys\nclass _Block:\n    def find_spec(self, name, path=None, target=None):\n"
        "        if name.split('.')[0] == 'flockkit' or name.startswith('flockkit_'):\n"
        "            raise ModuleNotFoundError(name, name=name)\n"
        "sys.meta_path.insert(0, _Block())\n"
    )
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    recording = work[0]
    with _start_workers(scheduler, env), joblib.parallel_config(backend="dask", n_jobs=-1):
        kind, what = outcome(lambda: flockkit.build_graph(recording, seed=0), seconds=60)  # a hang counts as one
    assert kind == "named" and "MissingDependencyError: a joblib worker cannot import 'flockkit" in what, what


def test_ray_gives_the_same_bytes(work):
    ray = pytest.importorskip("ray", reason="the Ray check needs the scale extra: pip install 'flockkit[scale]'")
    from ray.util.joblib import register_ray

    recording, problem, reference = work
    register_ray()
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        with joblib.parallel_config(backend="ray", n_jobs=2):
            _same(_results(recording, problem), reference)
    finally:
        ray.shutdown()


def test_the_cli_chooses_a_backend(work, tmp_path):
    recording, _, reference = work
    recording.save(tmp_path / "m.npz")
    kind, what = cli_outcome(["build", str(tmp_path / "m.npz"), "-o", str(tmp_path / "g.npz"), "--backend", "dask",
                              "--jobs", "2", "--quiet"])  # fmt: skip
    assert kind == "ok", what
    built = flockkit.MotionGraph.load(tmp_path / "g.npz")  # the CLI takes no seed: compare all but that
    assert built.transitions == reference[0].transitions and list(built.nodes) == list(reference[0].nodes)
