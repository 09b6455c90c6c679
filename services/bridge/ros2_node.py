"""The ``ros2`` flavour: the bridge as a ROS 2 node itself, through ``rclpy`` (SPEC §7).

Imported only when the flavour is enabled: ``rclpy`` and the message packages come from the
optional extra ``lunaris[ros2]`` (the ROS 2 wheels on PyPI), and the rest of Lunaris runs
without them. The ROS 2 environment is passed through (``RMW_IMPLEMENTATION``,
``FASTDDS_BUILTIN_TRANSPORTS``, ...); the domain of each rover is given explicitly.

One rclpy context and node per ROS 2 domain (a fleet gives each rover its own domain), each
spun by an executor on its own thread for the inbound topics and the services (the crew's
controls, answered when the twin has answered: :meth:`Ros2Graph.serve`). Messages cross as CDR bytes
both ways: a publisher is handed the bytes :mod:`services.bridge.cdr` already made for the
Zenoh flavours (each value is encoded once), and a subscription hands its raw bytes to the
same decoding as every other flavour.
"""

from __future__ import annotations

import importlib
import os
import threading
from collections.abc import Callable
from typing import Any

# a service's handler: the request's fields, and the function that sends the response's fields
# (from any thread, once)
ServiceCall = Callable[[dict[str, Any], Callable[[dict[str, Any]], None]], None]

__all__ = ["Ros2Unavailable", "Ros2Graph", "env_domain"]


class Ros2Unavailable(RuntimeError):
    """rclpy or a message package is missing: the ``ros2`` flavour cannot run."""


def env_domain() -> int:
    """``ROS_DOMAIN_ID`` of the environment, else 0 (ROS 2's default)."""
    value = os.environ.get("ROS_DOMAIN_ID", "").strip()
    return int(value) if value.isdigit() else 0


def _import(module: str) -> Any:
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise Ros2Unavailable(f"the ros2 flavour needs {module} ({exc}); install the extra: "
                              "pip install 'lunaris[ros2]'") from None


class Ros2Graph:
    """The bridge's ROS 2 nodes, one per domain, created on first use."""

    def __init__(self, node: str, namespace: str = "/"):
        self._rclpy = _import("rclpy")
        self._qos = _import("rclpy.qos")
        self._executors = _import("rclpy.executors")
        self._signals = _import("rclpy.signals")
        self._context_mod = _import("rclpy.context")
        self._node_mod = _import("rclpy.node")
        self._groups_mod = _import("rclpy.callback_groups")
        self._task_mod = _import("rclpy.task")
        self._service_groups: dict[int, Any] = {}
        self.node_name, self.namespace = node, namespace
        self._nodes: dict[int, tuple[Any, Any, Any, threading.Thread]] = {}
        self._lock = threading.Lock()
        q = self._qos
        # Outbound: the last value for a late joiner, as the twin's own telemetry.
        self.publisher_qos = q.QoSProfile(depth=1, history=q.HistoryPolicy.KEEP_LAST,
                                          reliability=q.ReliabilityPolicy.RELIABLE,
                                          durability=q.DurabilityPolicy.TRANSIENT_LOCAL)
        # Inbound: what a dashboard's default publisher offers (reliable, volatile).
        self.subscription_qos = q.QoSProfile(depth=10, history=q.HistoryPolicy.KEEP_LAST,
                                             reliability=q.ReliabilityPolicy.RELIABLE,
                                             durability=q.DurabilityPolicy.VOLATILE)

    @staticmethod
    def message_class(typename: str) -> Any:
        """``std_msgs/msg/Bool`` -> the class ``std_msgs.msg.Bool``."""
        pkg, kind, name = typename.split("/")
        module = _import(f"{pkg}.{kind}")
        try:
            return getattr(module, name)
        except AttributeError:
            raise Ros2Unavailable(f"{pkg}.{kind} has no {name}") from None

    def node(self, domain: int) -> Any:
        with self._lock:
            found = self._nodes.get(domain)
            if found is None:
                ctx = self._context_mod.Context()
                self._rclpy.init(context=ctx, domain_id=domain,
                                 signal_handler_options=self._signals.SignalHandlerOptions.NO)
                node = self._node_mod.Node(self.node_name, namespace=self.namespace, context=ctx)
                executor = self._executors.SingleThreadedExecutor(context=ctx)
                executor.add_node(node)
                thread = threading.Thread(target=self._spin, args=(executor,),
                                          name=f"ros2-domain-{domain}", daemon=True)
                thread.start()
                found = self._nodes[domain] = (ctx, node, executor, thread)
            return found[1]

    def _spin(self, executor: Any) -> None:
        try:
            executor.spin()
        except self._executors.ExternalShutdownException:
            pass  # the node is going away

    def publisher(self, domain: int, topic: str, typename: str) -> Any:
        """An rclpy publisher on a topic: its ``publish`` takes CDR bytes (with their
        encapsulation header), its ``get_subscription_count()`` says how many subscriptions
        it has matched."""
        return self.node(domain).create_publisher(self.message_class(typename), topic,
                                                  self.publisher_qos)

    def subscribe(self, domain: int, topic: str, typename: str,
                  callback: Callable[[bytes], None]) -> None:
        """Hand every message on a topic, as CDR bytes, to ``callback`` (an executor thread)."""
        self.node(domain).create_subscription(self.message_class(typename), topic, callback,
                                              self.subscription_qos, raw=True)

    def serve(self, domain: int, name: str, typename: str, call: ServiceCall) -> None:
        """Serve a ROS 2 service (``std_srvs/srv/SetBool``) whose answer comes later, from
        another thread: ``call(fields, respond)`` gets the request's fields and calls
        ``respond(fields)`` once with the response's. The rclpy callback is a coroutine that
        awaits an rclpy Future completed on the executor's own thread (``create_task``: a
        Future completed from another thread does not wake the executor), in a reentrant
        callback group, so that calls overlap instead of waiting for each other. The executor
        resumes a waiting coroutine only when something wakes it: the Future's result is set
        and the executor woken in the same task (else the answer waits for the next message
        or timer, forever on a quiet node)."""
        node = self.node(domain)
        executor = self._nodes[domain][2]
        group = self._service_groups.setdefault(domain, self._groups_mod.ReentrantCallbackGroup())
        srv_type = self.message_class(typename)
        asked = [f for f in srv_type.Request.get_fields_and_field_types()
                 if f != "structure_needs_at_least_one_member"]
        future_type = self._task_mod.Future

        async def callback(request: Any, response: Any) -> Any:
            fut = future_type(executor=executor)

            def settle(values: dict[str, Any]) -> None:
                if not fut.done():
                    fut.set_result(values)
                executor.wake()  # the service's coroutine is resumed on the next turn

            def respond(values: dict[str, Any]) -> None:
                executor.create_task(settle, values)
            call({f: getattr(request, f) for f in asked}, respond)
            for field, value in (await fut).items():
                setattr(response, field, value)
            return response

        node.create_service(srv_type, name, callback, callback_group=group)

    def close(self) -> None:
        with self._lock:
            nodes, self._nodes = self._nodes, {}
        for ctx, node, executor, thread in nodes.values():
            executor.shutdown()
            node.destroy_node()
            self._rclpy.shutdown(context=ctx)
            thread.join(timeout=2.0)
