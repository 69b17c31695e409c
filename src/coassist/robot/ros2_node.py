"""The life cycle of coassist's ROS 2 nodes: names, start-up, spinning and shutdown.

:class:`~coassist.robot.ros2_world.Ros2World` (``coassist ros2``) and
:class:`~coassist.robot.ros2_watchdog.CommandWatchdog` (``coassist ros2-watchdog``) each run
one rclpy node the same way, held by a :class:`Ros2Node`:

- start-up: a ``rclpy.Context`` of its own (``rclpy.init`` with the ``ROS_DOMAIN_ID`` asked
  for, else the environment's), so the process's global context is left alone and two
  nodes in one process shut down independently; then the node, named and namespaced;
- spinning (:meth:`Ros2Node.spin`, once the owner has made its publishers, subscriptions and
  timers): a ``SingleThreadedExecutor`` spun by a daemon thread of its own,
  ``spin_once(0.02 s)`` in a loop, so every callback runs on that one thread;
- shutdown (:meth:`Ros2Node.stop_spinning`, then :meth:`Ros2Node.shutdown`; :meth:`Ros2Node.close`
  does both): the thread stops first (joined at most 2 s), so that nothing it handles
  goes out after what the owner sends last (zero velocities); then the executor, the node
  and the context, each step tried even if one before failed: a node partly built, or shut
  down already, still closes. Neither raises.

The ROS names the two check (:data:`ROS_TOPIC`, :data:`ROS_NAME`, :func:`resolve_topic`) are here
too: they need no rclpy. Needs the ``ros2`` extra for :class:`Ros2Node`.
"""

from __future__ import annotations

import logging
import re
import threading
from typing import Any

__all__ = ["ROS_NAME", "ROS_TOPIC", "Ros2Node", "install_hint", "resolve_topic", "stamp_ns"]

log = logging.getLogger(__name__)

#: A topic name as the config fields accept it: absolute, ``~``-relative or relative.
ROS_TOPIC = re.compile(r"^~?/?[A-Za-z][A-Za-z0-9_]*(/[A-Za-z][A-Za-z0-9_]*)*$|^~$")
#: A node name or a namespace component.
ROS_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")


def stamp_ns(stamp: Any) -> int:
    """A ROS ``builtin_interfaces/Time`` (``sec``, ``nanosec``) as integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def install_hint(command: str) -> str:
    """What to install when ``coassist <command>`` finds no rclpy (or no message package)."""
    return f"coassist {command} needs the ros2 extra (rclpy and the message packages): pip install 'coassist[ros2]'"


def resolve_topic(name: str, node_name: str, namespace: str = "") -> str:
    """The fully qualified name ROS 2 gives ``name`` on node ``node_name`` in ``namespace``:
    ``/x`` stays, ``~/x`` is ``<ns>/<node>/x``, a relative ``x`` is ``<ns>/x``."""
    ns = "/" + namespace.strip("/") if namespace.strip("/") else ""
    if name.startswith("/"):
        full = name
    elif name == "~" or name.startswith("~/"):
        full = f"{ns}/{node_name}{name[1:]}"
    else:
        full = f"{ns}/{name}"
    return "/" + "/".join(part for part in full.split("/") if part)


class Ros2Node:
    """An rclpy node in a context of its own, spun by a thread of its own (module docstring).

    Parameters
    ----------
    name : the node's name.
    namespace : its namespace (None: the root).
    domain_id : ROS_DOMAIN_ID (None: the environment's).
    owner : who holds it, for the log (``"Ros2World"``) and the error's install hint.
    command : the ``coassist`` command it serves, for the install hint (``"ros2"``).
    thread_name : the spin thread's name.

    Attributes
    ----------
    node : the ``rclpy`` node: the owner makes its publishers, subscriptions and timers on it.
    context : its ``rclpy.Context``.
    """

    def __init__(
        self,
        name: str,
        *,
        namespace: str | None = None,
        domain_id: int | None = None,
        owner: str,
        command: str,
        thread_name: str,
    ) -> None:
        try:
            import rclpy
        except ImportError as exc:
            raise ImportError(f"{install_hint(command)} ({exc})") from exc
        self._rclpy = rclpy
        self._owner = owner
        self._thread_name = thread_name
        self._spinning = False
        self._thread: threading.Thread | None = None
        self._executor: Any = None
        self.node: Any = None
        self.context = rclpy.Context()
        init_args: dict[str, Any] = {"context": self.context}
        if domain_id is not None:
            init_args["domain_id"] = domain_id
        rclpy.init(**init_args)
        try:
            self.node = rclpy.create_node(name, namespace=namespace, context=self.context)
        except BaseException:
            self.shutdown()
            raise

    def spin(self) -> None:
        """Add the node to a single-threaded executor and start the thread that spins it."""
        from rclpy.executors import SingleThreadedExecutor

        self._executor = SingleThreadedExecutor(context=self.context)
        self._executor.add_node(self.node)
        self._spinning = True
        self._thread = threading.Thread(target=self._spin, name=self._thread_name, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        while self._spinning:
            try:
                self._executor.spin_once(timeout_sec=0.02)
            except Exception as exc:  # noqa: BLE001 - a shutdown race ends the thread
                if self._spinning:
                    log.warning("%s: executor stopped: %s", self._owner, exc)
                return

    def stop_spinning(self) -> None:
        """Stop the spin thread (joined at most 2 s): no callback runs after it returns."""
        self._spinning = False
        if self._thread is not None:
            self._thread.join(timeout=2.0)

    def shutdown(self) -> None:
        """Shut the executor, the node and the context down, each step tried; never raises."""
        for step in (
            lambda: self._executor.shutdown(timeout_sec=1.0),
            lambda: self.node.destroy_node(),
            lambda: self._rclpy.shutdown(context=self.context),
        ):
            try:
                step()
            except Exception:  # noqa: BLE001 - partly built, or already shut down
                pass

    def close(self) -> None:
        """:meth:`stop_spinning`, then :meth:`shutdown`; never raises."""
        self.stop_spinning()
        self.shutdown()
