"""The daemon's metrics for a print farm's monitoring, in Prometheus text format (the official prometheus-client).

Served on ``http://<[metrics] listen>/metrics`` when ``[metrics] enabled``.
The daemon's loop updates the counters and histograms (prometheus-client's
values are safe to read from its server thread); they count from the
daemon's start, as Prometheus expects. The job gauges are read from the
journal at each scrape, on a read-only connection of the server thread's
own, so they are the journal's state at that moment, every job it knows.
"""

from __future__ import annotations

import platform
from pathlib import Path

from prometheus_client import (
    CollectorRegistry,
    Counter,
    Gauge,
    Histogram,
    Info,
    ProcessCollector,
    start_http_server,
)
from prometheus_client.core import GaugeMetricFamily
from prometheus_client.registry import Collector

from fcso import __version__ as fcso_version

from .. import __version__
from ..config import MetricsConfig, split_host_port
from .journal import read_jobs

#: Upper bounds of the stage-duration buckets, s: a load takes under a second, a design minutes.
STAGE_BUCKETS_S = (0.1, 0.25, 0.5, 1, 2.5, 5, 10, 30, 60, 120, 300, 600, 1800, float("inf"))

#: The job states, each a label value of ``fcsod_jobs`` (a state without jobs reads 0, not absent).
STATES = ("queued", "running", "done", "failed", "held")


class JournalCollector(Collector):
    """``fcsod_jobs{state}`` and ``fcsod_queue_depth``, counted in the journal at each scrape."""

    def __init__(self, journal_path: Path):
        self.journal_path = journal_path

    def collect(self):
        by_state = dict.fromkeys(STATES, 0)
        for row in read_jobs(self.journal_path):
            by_state[row.state] += 1
        jobs = GaugeMetricFamily("fcsod_jobs", "Jobs in the journal, by state", labels=["state"])
        for state, count in by_state.items():
            jobs.add_metric([state], count)
        yield jobs
        yield GaugeMetricFamily("fcsod_queue_depth", "Jobs queued and not started yet", value=by_state["queued"])


class DaemonMetrics:
    """The daemon's metrics in a registry of their own.

    Parameters
    ----------
    journal_path : Path
        The journal the job gauges are read from.
    """

    def __init__(self, journal_path: Path) -> None:
        self.registry = CollectorRegistry()
        self.registry.register(JournalCollector(journal_path))
        # the daemon process's CPU, memory, open files and start time (process_*), as every exporter has them
        ProcessCollector(registry=self.registry)
        Info("fcsod_build", "The running daemon's versions", registry=self.registry).info(
            {"version": __version__, "fcso_version": fcso_version, "python_version": platform.python_version()}
        )
        self.job_seconds = Histogram(
            "fcsod_job_duration_seconds",
            "Duration of a job from its start to its final state, by that state, s",
            ["state"],
            buckets=STAGE_BUCKETS_S,
            registry=self.registry,
        )
        self.last_success = Gauge(
            "fcsod_last_success_timestamp_seconds",
            "When a job last ended done, s since the epoch (0 before any)",
            registry=self.registry,
        )
        self.jobs_finished = Counter(
            "fcsod_jobs_finished",
            "Jobs this daemon run finished, by final state (done, failed, held, or cancelled by an operator)",
            ["state"],
            registry=self.registry,
        )
        self.stage_seconds = Histogram(
            "fcsod_stage_duration_seconds",
            "Duration of a job's steps (load, design, build, ...), s",
            ["stage"],
            buckets=STAGE_BUCKETS_S,
            registry=self.registry,
        )
        self.verifications = Counter(
            "fcsod_verifications",
            "Designs verified in simulation, by result (passed or failed)",
            ["result"],
            registry=self.registry,
        )
        self.verification_pass_ratio = Gauge(
            "fcsod_verification_pass_ratio",
            "Share of the designs verified since the daemon started that passed (0 before any)",
            registry=self.registry,
        )
        self.publish_failures = Counter(
            "fcsod_bus_publish_failures",
            "Messages that could not be published, by transport (zenoh, ros2 or foxglove)",
            ["transport"],
            registry=self.registry,
        )
        # cancelled (fcsod cancel) apart from failed: an operator's decision, not a fault
        for state in ("done", "failed", "held", "cancelled"):
            self.jobs_finished.labels(state)
        for result in ("passed", "failed"):
            self.verifications.labels(result)
        for transport in ("zenoh", "ros2", "foxglove"):
            self.publish_failures.labels(transport)
        self._server = None
        self._verified = {"passed": 0, "failed": 0}

    def serve(self, config: MetricsConfig) -> None:
        """Start the HTTP endpoint on ``config.listen`` (a thread of prometheus-client's)."""
        host, port = split_host_port(config.listen)
        self._server, _ = start_http_server(port, addr=host, registry=self.registry)

    def close(self) -> None:
        if self._server is not None:
            self._server.shutdown()
            self._server.server_close()

    def verified(self, passed: bool) -> None:
        """Count one verified design."""
        result = "passed" if passed else "failed"
        self.verifications.labels(result).inc()
        self._verified[result] += 1
        self.verification_pass_ratio.set(self._verified["passed"] / sum(self._verified.values()))
