"""The design's fan-out on a Dask distributed cluster: a LocalCluster the test starts itself (2 single-thread worker
processes), against the local forked workers, on a small job of the knob parts of tests/fcso/test_sets.py.
"""

import json
import os
import signal

import pytest
from distributed import LocalCluster, WorkerPlugin

from fcso.sets import design_sets
from tests.fcso.test_sets import NARROWING, NARROWING_BIG_PLATE, NARROWING_WIDER, WIDENING, config


def report_without_timings(result) -> dict:
    """The job's report.json as written, timings aside (the only field that varies between identical runs)."""
    report = json.loads(result.job().model_dump_json())
    report.pop("timings_s")
    return report


class KillOnFirstTask(WorkerPlugin):
    """Kills its worker's process (SIGKILL, as the OOM killer would) when the first task of the whole cluster starts.

    The first is decided by creating ``marker`` exclusively: whichever worker's task starts first dies, once; the
    kill does not depend on timing.
    """

    def __init__(self, marker: str):
        self.marker = marker

    def transition(self, key, start, finish, **kwargs):
        if finish != "executing":
            return
        try:
            os.close(os.open(self.marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
        except FileExistsError:
            return
        os.kill(os.getpid(), signal.SIGKILL)


#: The jobs run on the cluster, each also run locally: (parts, settings). Above exhaustive_parts the search for many
#: parts runs (carving descriptors, nearest pairs, moves); one part is the shortest job that still fans out every stage.
JOBS = {
    "two knobs": ([NARROWING, WIDENING], {}),
    "four knobs, scaled search": (
        [NARROWING, WIDENING, NARROWING_WIDER, NARROWING_BIG_PLATE],
        {"finger_sets": {"exhaustive_parts": 1, "pairs_per_part": 1, "max": 2}},
    ),
    "one knob": ([NARROWING], {}),
}


@pytest.fixture(scope="module")
def local_reports():
    """Each job's report on local forked workers, all designed before the cluster starts: a process forked while the
    cluster's event loop thread runs in this one could inherit a lock that thread holds."""
    return {
        name: report_without_timings(design_sets(parts, config(**settings))) for name, (parts, settings) in JOBS.items()
    }


@pytest.fixture(scope="module")
def cluster(local_reports):
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as local:
        yield local


def on_cluster(name: str, cluster) -> dict:
    """Job ``name`` of :data:`JOBS` designed on ``cluster``: its report as :func:`report_without_timings`."""
    parts, settings = JOBS[name]
    return report_without_timings(
        design_sets(parts, config(compute={"scheduler": cluster.scheduler_address}, **settings))
    )


def test_a_dask_cluster_gives_the_local_report(cluster, local_reports):
    assert on_cluster("two knobs", cluster) == local_reports["two knobs"]
    # where the work ran changes no result, so the report's settings leave it out
    assert "compute" not in local_reports["two knobs"]["settings"]


def test_the_scaled_partition_search_on_a_dask_cluster_gives_the_local_report(cluster, local_reports):
    local = local_reports["four knobs, scaled search"]
    assert local["finger_sets"]["search"]["method"] == "carving_neighbours+colouring+local_moves"
    # these four knobs share carvings: their pad's thinnest wall differed on Dask (9.077406 against 9.080566) while
    # manifold3d's union triangulated a carving given twice as one object locally and as two on the cluster
    assert on_cluster("four knobs, scaled search", cluster) == local


def test_a_worker_killed_mid_job_costs_a_retry_not_the_job(cluster, local_reports, tmp_path):
    marker = tmp_path / "killed"
    with cluster.get_client() as client:
        client.register_plugin(KillOnFirstTask(str(marker)), name="kill-on-first-task")
        try:
            result = on_cluster("one knob", cluster)
        finally:
            client.unregister_worker_plugin("kill-on-first-task")
    assert marker.exists()  # a worker did die mid-job
    assert result == local_reports["one knob"]
