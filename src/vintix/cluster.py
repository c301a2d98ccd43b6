"""Optional Ray fan-out for `vintix collect --ray` and `vintix eval --ray`.

Both commands already split their work into independent, reproducible units (a batch of histories,
a batch of evaluation runs); this module only ships those units to Ray workers, one CPU each, and
hands the results back as they finish, so a cluster gives the same files and rows as local
processes. Ray is an optional extra (``pip install 'vintix[cluster]'``): it is imported here, on
first use, never when vintix is imported.
"""

from __future__ import annotations

import os
import resource
import socket
from collections.abc import Callable, Iterator, Sequence
from types import ModuleType
from typing import Any, TypeVar
from urllib.parse import urlsplit

from tqdm import tqdm

from vintix.errors import MissingDependencyError, VintixError

INSTALL = "pip install 'vintix[cluster]'"
# Workers' own progress bars reach the driver as log lines, which would bury the driver's bar;
# tqdm reads TQDM_* variables when it is imported, so they are set for each worker process.
WORKER_ENV = {"env_vars": {"TQDM_DISABLE": "1"}}

R = TypeVar("R")


class ClusterUnreachableError(VintixError):
    """Nothing answers at the Ray cluster address given (by --ray or RAY_ADDRESS)."""


class ClusterStartError(VintixError):
    """Ray came up, but its workers do not: no task would ever run."""


def import_ray() -> ModuleType:
    """The `ray` module, or an error that says how to install it (it is an optional extra)."""
    try:
        import ray
    except ImportError:
        raise MissingDependencyError(
            f"--ray needs Ray, which is not installed here: {INSTALL} (on every node of the cluster, with the "
            "versions of requirements.lock)") from None
    return ray


def connect(address: str) -> None:
    """Attach this process to a Ray cluster, unless it already is (a test or a notebook connected first).

    ``"auto"`` is ``ray.init()`` with no address, not Ray's own ``address="auto"``: it joins the cluster
    that ``RAY_ADDRESS`` or the latest ``ray start`` on this machine names, and where there is none it
    starts a local Ray instance (a laptop), where Ray's ``"auto"`` would fail. Anything else
    (``host:6379``, ``ray://host:10001``) must be a running cluster. Whichever address is to be joined
    must answer first (`check_reachable`): Ray itself would retry a dead one for minutes.
    """
    ray = import_ray()
    if ray.is_initialized():
        return
    refuse_address_space_limit(address)
    if address != "auto":
        check_reachable(address, "--ray", "start it (ray start --head) or correct the address")
    elif os.environ.get("RAY_ADDRESS"):
        check_reachable(os.environ["RAY_ADDRESS"], "RAY_ADDRESS",
                        "start it, correct RAY_ADDRESS, or unset it so that --ray auto starts a local instance")
    else:
        # ray.init() joins the cluster the latest `ray start` here recorded in a file, which stays behind
        # when that cluster dies without `ray stop`. Ray's own lookup (private, so pinned with Ray's version).
        from ray._private.services import canonicalize_bootstrap_address

        recorded = canonicalize_bootstrap_address(None)  # type: ignore[arg-type]  # documented to take None
        if recorded:
            check_reachable(recorded, "the latest `ray start` on this machine",
                            "start it again, or run `ray stop` to forget it so that --ray auto starts a local instance")
    ray.init(address=None if address == "auto" else address)
    check_workers_start(ray)


def refuse_address_space_limit(address: str) -> None:
    """ClusterStartError where this process has an address-space limit (`ulimit -v`, as clusters and containers
    set) and would start or join Ray on this machine: Ray maps its shared object store into every process,
    which such a limit refuses, and Ray then aborts in C++ (or its workers never start) instead of failing.
    A Ray client (``ray://``) maps no store here."""
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft != resource.RLIM_INFINITY and not address.startswith("ray://"):
        raise ClusterStartError(
            f"this process runs under an address-space limit (ulimit -v {soft // 1024}), under which Ray cannot map "
            "its object store: lift it for this command (ulimit -v unlimited), connect as a Ray client (--ray "
            "ray://HOST:10001), or run without --ray")


WORKER_START_SECONDS = 60.0
"""How long a cluster may take to run a first, empty task before `connect` gives up on it"""


def _alive() -> bool:
    return True


def check_workers_start(ray: ModuleType, timeout: float = WORKER_START_SECONDS) -> None:
    """Raise ClusterStartError unless an empty task runs within `timeout` seconds: where Ray's workers cannot
    start (an address-space limit, `ulimit -v`, as clusters and containers set, is the usual cause), every
    task would wait forever."""
    try:
        ray.get(ray.remote(_alive).options(num_cpus=0).remote(), timeout=timeout)
    except ray.exceptions.GetTimeoutError:
        ray.shutdown()
        raise ClusterStartError(f"Ray started, but no worker ran an empty task within {timeout:.0f} s: see Ray's logs "
                                "(/tmp/ray/session_latest/logs) for why its workers do not start") from None


def check_reachable(address: str, source: str, fix: str, timeout: float = 10.0) -> None:
    """Raise ClusterUnreachableError (naming `source` and `fix`) unless something listens at `address`'s
    host and port: `ray.init` retries an address where no cluster runs for minutes, printing connection
    warnings, instead of failing. Addresses without a port (Ray's own "auto") are left to Ray."""
    parts = urlsplit(address if "://" in address else f"//{address}")
    try:
        host, port = parts.hostname, parts.port
    except ValueError:  # a port that is not a number
        host, port = None, None
    if not host or port is None:
        return
    try:
        socket.create_connection((host, port), timeout=timeout).close()
    except OSError as error:
        raise ClusterUnreachableError(f"no Ray cluster answers at {address} (from {source}): {error}; {fix}") from None


def map_tasks(function: Callable[..., R], calls: Sequence[tuple[Any, ...]], description: str,
              progress: bool = True) -> Iterator[tuple[int, R]]:
    """``function(*call)`` for every call, each a Ray task of one CPU on the connected cluster; yields
    ``(index of the call, result)`` in the order tasks finish, so callers that need the calls' order
    restore it by index. With `progress`, a bar (on a terminal) advances as tasks finish.
    A task's error is raised as the error it raised in the worker; tasks still pending are cancelled."""
    ray = import_ray()
    remote = ray.remote(function).options(num_cpus=1, runtime_env=WORKER_ENV)
    pending = {remote.remote(*call): index for index, call in enumerate(calls)}
    with tqdm(total=len(pending), desc=description, disable=None if progress else True) as bar:
        try:
            while pending:
                [ready], _ = ray.wait(list(pending), num_returns=1)
                index, result = pending.pop(ready), _result(ray, ready)
                bar.update(1)
                yield index, result
        finally:
            for ref in pending:
                ray.cancel(ref)


def _result(ray: ModuleType, ref: Any) -> Any:
    """The task's value; a task that raised re-raises its own error (a VintixError stays one, with
    its message), chained to Ray's error, which carries the worker's traceback."""
    try:
        return ray.get(ref)
    except ray.exceptions.RayTaskError as error:
        if isinstance(error.cause, Exception):
            raise error.cause from error
        raise
