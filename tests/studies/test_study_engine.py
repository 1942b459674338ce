"""The local cluster's start-up: its workers ignore Ctrl-C, and a Ctrl-C meanwhile stops
the study once the cluster is up instead of being lost."""

from __future__ import annotations

import contextlib
import signal
import threading
import time

import distributed
import pytest

from hydrojet_bench.studies.engine import dask_client


class StartingCluster:
    """A stand-in `LocalCluster`: Ctrl-C arrives while it starts its workers."""

    def __init__(self, **_: object) -> None:
        self.closed = False
        # Workers started now inherit this: ignored, they print no traceback of their own.
        self.disposition = signal.getsignal(signal.SIGINT)
        signal.pthread_kill(threading.get_ident(), signal.SIGINT)
        time.sleep(0.05)  # the start-up goes on: nothing raised here

    def __enter__(self) -> StartingCluster:
        return self

    def __exit__(self, *_: object) -> None:
        self.closed = True


def test_ctrl_c_during_the_start_up_stops_once_the_cluster_is_up(monkeypatch: pytest.MonkeyPatch):
    started = []
    monkeypatch.setattr(distributed, "LocalCluster", lambda **kwargs: started.append(StartingCluster()) or started[-1])
    monkeypatch.setattr(distributed, "Client", lambda cluster: pytest.fail("a client on an interrupted start-up"))
    handler = signal.getsignal(signal.SIGINT)
    with pytest.raises(KeyboardInterrupt):
        with dask_client(workers=1):
            pytest.fail("the study ran on")
    assert started[0].disposition == signal.SIG_IGN and started[0].closed
    assert signal.getsignal(signal.SIGINT) is handler
    assert signal.SIGINT not in signal.pthread_sigmask(signal.SIG_BLOCK, set())


def test_the_dashboard_port_warning_of_a_cluster_without_dashboard_is_silenced(monkeypatch: pytest.MonkeyPatch):
    import warnings

    class Cluster(StartingCluster):
        def __init__(self, **kwargs: object) -> None:
            assert kwargs["dashboard_address"] is None
            warnings.warn("Port 8787 is already in use.\nPerhaps you already have a cluster running?", UserWarning)
            self.closed = False

    monkeypatch.setattr(distributed, "LocalCluster", Cluster)
    monkeypatch.setattr(distributed, "Client", lambda cluster: contextlib.nullcontext(cluster))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with dask_client(workers=1):
            pass
    assert caught == []
