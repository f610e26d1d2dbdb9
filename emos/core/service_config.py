"""``ServiceClientConfig``: a named service of the run and its type (the ROS original's class).

    from emos import ServiceClientConfig
    from emos.actors.nav.components.interfaces import PathFromToFile

    save = ServiceClientConfig(name=f"{planner.node_name}/save_plan_to_file", srv_type=PathFromToFile)
    save.call(file_location="/tmp", file_name="path.csv")       # from any process of the run
    events_actions = {event: save.send_request(PathFromToFile.Request(...))}  # from an event
    launcher.enable_ui(inputs=[save])                          # a form on the web page

``srv_type`` is a service type: a class with ``Request`` and ``Response`` message classes (the
``kompass_interfaces.srv`` types are in ``emos.actors.nav.components.interfaces``), or a
``(Request, Response)`` pair of message classes or names. The name and the type are checked
here, at definition, with an error naming the service. Calls go over the run's service sockets
(:mod:`emos.core.services`): ``timeout_secs`` bounds the wait for the service to be there and
for its answer, ``attempt_period_secs`` is how often a missing service is tried again.
"""
from __future__ import annotations

from typing import Any

import attrs
from attrs import define, field

from emos.config import validators as V
from emos.errors import TransportError
from emos.msgs.registry import resolve

__all__ = ["ServiceClientConfig", "service_types"]


def service_types(srv_type: Any, where: str) -> tuple[type, type]:
    """(request class, response class) of a service type; TypeError naming ``where`` otherwise."""
    if isinstance(srv_type, (tuple, list)) and len(srv_type) == 2:
        parts: tuple[Any, Any] = (srv_type[0], srv_type[1])
    elif hasattr(srv_type, "Request") and hasattr(srv_type, "Response"):
        parts = (srv_type.Request, srv_type.Response)
    else:
        raise TypeError(f"{where}: srv_type must be a service type with .Request and .Response message classes "
                        f"(e.g. emos.actors.nav.components.interfaces.PathFromToFile) or a (Request, Response) pair, "
                        f"got {getattr(srv_type, '__name__', type(srv_type).__name__)} {srv_type!r}")
    try:
        request, response = (resolve(p) for p in parts)
    except Exception as exc:
        raise TypeError(f"{where}: srv_type {srv_type!r}: its Request and Response must be EMOS message types ({exc})") from None
    return request, response


def _check_name(instance: Any, attribute: attrs.Attribute[Any], value: Any) -> None:
    from emos.io.topic import normalize_topic_name

    try:
        normalize_topic_name(value)  # services follow the topic naming rules (and length limit)
    except (TypeError, ValueError) as exc:
        reason = str(exc).replace("Topic name", "the name")
        raise ValueError(f"ServiceClientConfig: name must be a service name like 'planner/save_plan_to_file' "
                         f"(letters, digits and '_', separated by '/'), got {value!r} ({reason})") from None


def _check_type(instance: Any, attribute: attrs.Attribute[Any], value: Any) -> None:
    service_types(value, f"ServiceClientConfig(name={getattr(instance, 'name', '?')!r})")


@define
class ServiceClientConfig:
    """A service of the run (``name``, as its component created it) and its type (``srv_type``)."""

    srv_type: Any = field(validator=_check_type)
    name: str = field(validator=_check_name)
    timeout_secs: float = field(default=30.0, validator=V.number(gt=0))
    attempt_period_secs: float = field(default=1.0, validator=V.number(gt=0))

    @property
    def request_type(self) -> type:
        return service_types(self.srv_type, self._where)[0]

    @property
    def response_type(self) -> type:
        return service_types(self.srv_type, self._where)[1]

    @property
    def _where(self) -> str:
        return f"service {self.name!r}"

    def request(self, request: Any = None, **fields: Any) -> Any:
        """``request`` checked against the service's request type, or one built from ``fields``."""
        req_t = self.request_type
        if request is None:
            try:
                return req_t(**fields)
            except TypeError as exc:
                known = ", ".join(f.name for f in attrs.fields(req_t))
                raise TypeError(f"{self._where}: cannot build a {req_t.__name__} from {sorted(fields)} ({exc}); its fields are {known}") from None
        if fields:
            raise TypeError(f"{self._where}: give a request or its fields, not both")
        if not isinstance(request, req_t):
            raise TypeError(f"{self._where} takes {req_t.__name__}, got {type(request).__name__}")
        return request

    def client(self, ctx: Any = None) -> Any:
        """A blocking :class:`~emos.core.services.ServiceClient` of this service (in the current run)."""
        from emos.core.services import ServiceClient

        return ServiceClient(self.name, self.request_type, self.response_type, ctx=ctx, timeout=self.timeout_secs)

    def call(self, request: Any = None, *, ctx: Any = None, **fields: Any) -> Any:
        """Call the service and return its response. A service that is not there yet (its
        component still starting) is tried again every ``attempt_period_secs`` for up to
        ``timeout_secs``; then TransportError names the service and the last failure."""
        from emos.core.retry import Backoff, retry
        from emos.core.rpc import RpcConnectionError

        req = self.request(request, **fields)
        client = self.client(ctx)
        try:
            return retry(lambda: client.call(req), Backoff(base=self.attempt_period_secs, factor=1.0, timeout=self.timeout_secs),
                         retry_on=RpcConnectionError)
        except RpcConnectionError as exc:
            raise TransportError(f"{self._where} ({self.request_type.__name__}) did not answer within {self.timeout_secs:g} s: {exc}") from None
        finally:
            client.close()

    # -- as actions of events and fallbacks (run by the Monitor) -----------------------------------
    def send_request(self, request: Any = None, **fields: Any) -> Any:
        """An Action that calls the service with ``request`` (or one built from ``fields``)."""
        from emos.actions import send_srv_request

        return send_srv_request(srv_name=self.name, srv_type=(self.request_type, self.response_type),
                                srv_request_msg=self.request(request, **fields))

    def trigger(self) -> Any:
        """An Action that calls the service with a request made from the event's message
        (fields with the same names), else the default request."""
        from emos.actions import trigger_service

        return trigger_service(srv_name=self.name, srv_type=(self.request_type, self.response_type))
