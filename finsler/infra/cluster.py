"""Joining a Ray cluster, shared by ``solvers`` (batches of exact geodesics) and ``learn``
(sweeps of training runs), which may not import each other.

Ray is optional (``pip install -e '.[distributed]'``) and imported only when asked for.
A wrong address must fail in seconds with the address in the message: before handing a
``HOST:PORT`` (or ``ray://HOST:PORT``) address to ``ray.init`` (whose GCS client retries
for minutes), the port is probed with a plain TCP connection.
"""

from __future__ import annotations

import logging
import os
import socket
from typing import Any

from finsler.errors import InputError

__all__ = ["PROBE_SECONDS", "RAY_MISSING", "connect_ray", "probe_address", "require_ray"]

RAY_MISSING = ("--ray needs Ray, which is not installed: pip install -e '.[distributed]' "
               "(or pip install 'ray>=2.9')")
PROBE_SECONDS = 5.0
"""How long a TCP connection to the cluster's address may take before it is declared
unreachable."""


def require_ray() -> Any:
    """The ``ray`` module, or `InputError` saying how to install it."""
    try:
        import ray
    except ImportError as err:
        raise InputError(RAY_MISSING) from err
    return ray


def _host_port(address: str) -> tuple[str, int] | None:
    """``(host, port)`` of ``HOST:PORT`` or ``ray://HOST:PORT``; None for ``auto``/``local``.
    A malformed address raises `InputError`."""
    if address in ("auto", "local"):
        return None
    rest = address.removeprefix("ray://")
    host, sep, port = rest.rpartition(":")
    host = host.strip("[]")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise InputError(f"--ray address {address!r} is not HOST:PORT, ray://HOST:PORT, "
                         "auto or local")
    return host, int(port)


def probe_address(address: str, seconds: float = PROBE_SECONDS) -> None:
    """Raise `InputError` unless a TCP connection to ``address``'s host and port
    opens within ``seconds`` (no-op for ``auto`` and ``local``)."""
    hp = _host_port(address)
    if hp is None:
        return
    try:
        with socket.create_connection(hp, timeout=seconds):
            pass
    except OSError as err:
        reason = (f"no answer within {seconds:g} s" if isinstance(err, TimeoutError)
                  else (err.strerror or str(err)).lower())
        raise InputError(f"cannot connect to Ray at {address!r}: nothing answers at "
                         f"{hp[0]}:{hp[1]} ({reason}); start "
                         "the cluster with `ray start --head` or check the address") from err


def connect_ray(address: str, num_cpus: int | None = None) -> bool:
    """Join the Ray cluster at ``address`` (``"auto"``, ``"HOST:PORT"``, ``"ray://..."``)
    or start a local instance (``"local"``, ``num_cpus`` CPUs), quietly (no worker logs
    on the driver, no dashboard for a local instance). Returns False if Ray was already
    initialised in this process (it is then used as it is and left running), True if this
    call connected (the caller shuts it down). An unreachable address fails within
    `PROBE_SECONDS`."""
    ray = require_ray()
    if not isinstance(address, str) or not address.strip():
        raise InputError("--ray needs an address: HOST:PORT, auto, or local")
    address = address.strip()
    if ray.is_initialized():
        return False
    probe_address(address)
    quiet = dict(log_to_driver=False, logging_level=logging.ERROR)
    try:
        if address == "local":
            os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
            ray.init(num_cpus=num_cpus, include_dashboard=False, **quiet)
        else:
            ray.init(address=address, **quiet)
    except (ConnectionError, RuntimeError, ValueError) as err:
        raise InputError(f"cannot connect to Ray at {address!r}: {err}") from err
    return True
