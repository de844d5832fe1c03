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


@pytest.fixture(scope="module")
def cluster():
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as local:
        yield local


@pytest.fixture(scope="module")
def local_report():
    return report_without_timings(design_sets([NARROWING, WIDENING], config()))


def test_a_dask_cluster_gives_the_local_report(cluster, local_report):
    on_cluster = design_sets([NARROWING, WIDENING], config(compute={"scheduler": cluster.scheduler_address}))
    assert report_without_timings(on_cluster) == local_report
    # where the work ran changes no result, so the report's settings leave it out
    assert "compute" not in local_report["settings"]


def test_the_scaled_partition_search_on_a_dask_cluster_gives_the_local_report(cluster):
    # above exhaustive_parts the search for many parts runs (carving descriptors, nearest pairs, moves): the same
    parts = [NARROWING, WIDENING, NARROWING_WIDER, NARROWING_BIG_PLATE]
    settings = {"finger_sets": {"exhaustive_parts": 1, "pairs_per_part": 1, "max": 2}}
    local = design_sets(parts, config(**settings))
    on_cluster = design_sets(parts, config(compute={"scheduler": cluster.scheduler_address}, **settings))
    assert local.report.search.method == "carving_neighbours+colouring+local_moves"
    # these four knobs share carvings: their pad's thinnest wall differed on Dask (9.077406 against 9.080566) while
    # manifold3d's union triangulated a carving given twice as one object locally and as two on the cluster
    assert report_without_timings(on_cluster) == report_without_timings(local)


def test_a_worker_killed_mid_job_costs_a_retry_not_the_job(cluster, tmp_path):
    # one part: the shortest job that still fans out every stage
    local = report_without_timings(design_sets([NARROWING], config()))
    marker = tmp_path / "killed"
    with cluster.get_client() as client:
        client.register_plugin(KillOnFirstTask(str(marker)), name="kill-on-first-task")
        try:
            result = design_sets([NARROWING], config(compute={"scheduler": cluster.scheduler_address}))
        finally:
            client.unregister_worker_plugin("kill-on-first-task")
    assert marker.exists()  # a worker did die mid-job
    assert report_without_timings(result) == local
