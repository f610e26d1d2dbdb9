"""RoboML HTTP and WebSocket endpoints: ``/``, ``/add_node``, ``/remove_node``,
``/{node}/initialize``, ``/{node}/inference``, ``/{node}/get_status``, ``/{node}/ws_inference``."""
from __future__ import annotations

import weakref

import msgpack
from aiohttp import WSCloseCode, WSMsgType, web

from .common import in_thread, iterate_in_thread, read_json
from .guard import takes_json, takes_no_body
from .limits import MAX_WS_MESSAGE, unpack_msgpack
from .roboml_nodes import STREAM_END, NodeError, RoboMLNodes

__all__ = ["add_roboml_routes"]


def _error(exc: NodeError) -> web.Response:
    return web.json_response({"detail": str(exc)}, status=exc.status)


def add_roboml_routes(app: web.Application, nodes: RoboMLNodes) -> None:
    sockets: weakref.WeakSet[web.WebSocketResponse] = weakref.WeakSet()

    async def close_sockets(_app: web.Application) -> None:
        # Open websockets would otherwise hold shutdown until the runner's timeout.
        for ws in list(sockets):
            await ws.close(code=WSCloseCode.GOING_AWAY, message=b"server shutdown")

    app.on_shutdown.append(close_sockets)
    async def about(_request: web.Request) -> web.Response:
        return web.json_response({"title": "emos local model server (RoboML-compatible)", "apps_served": list(nodes.nodes)})

    @takes_no_body
    async def add_node(request: web.Request) -> web.Response:
        try:
            status, body = nodes.add_node(request.query.get("node_name", ""), request.query.get("node_model", ""))
        except NodeError as exc:
            return _error(exc)
        return web.json_response(body, status=status)

    @takes_no_body
    async def remove_node(request: web.Request) -> web.Response:
        try:
            return web.json_response(nodes.remove_node(request.query.get("node_name", "")), status=202)
        except NodeError as exc:
            return _error(exc)

    @takes_json
    async def initialize(request: web.Request) -> web.Response:
        try:
            body = await read_json(request)
            nodes.initialize(request.match_info["node"], body if isinstance(body, dict) else None)
        except ValueError as exc:
            return web.json_response({"detail": str(exc)}, status=400)
        except NodeError as exc:
            return _error(exc)
        return web.json_response(None)

    async def get_status(request: web.Request) -> web.Response:
        try:
            return web.json_response(nodes.status(request.match_info["node"]))
        except NodeError as exc:
            return _error(exc)

    @takes_json
    async def inference(request: web.Request) -> web.StreamResponse:
        try:
            body = await read_json(request)
            result = await in_thread(nodes.inference, request.match_info["node"], body)
        except ValueError as exc:
            return web.json_response({"detail": str(exc)}, status=400)
        except NodeError as exc:
            return _error(exc)
        if isinstance(result, dict):
            return web.json_response(result)
        stream = web.StreamResponse(headers={"Content-Type": "text/plain; charset=utf-8"})
        await stream.prepare(request)
        async for piece in iterate_in_thread(result):
            await stream.write(piece.encode())
        await stream.write_eof()
        return stream

    async def ws_inference(request: web.Request) -> web.WebSocketResponse:
        ws = web.WebSocketResponse(max_msg_size=MAX_WS_MESSAGE)
        await ws.prepare(request)
        sockets.add(ws)
        name = request.match_info["node"]
        async for message in ws:
            if message.type != WSMsgType.BINARY:
                await ws.close(code=1003, message=b"expected msgpack binary frames")
                break
            try:
                data = unpack_msgpack(message.data)
            except (ValueError, msgpack.ExtraData, msgpack.FormatError, msgpack.StackError):
                await ws.close(code=1007, message=b"payload is not msgpack")
                break
            if isinstance(data, dict) and data.get("query") == b"\r\n":  # keep-alive probe
                await ws.send_bytes(msgpack.packb(b"\r\n"))
                continue
            try:
                result = await in_thread(nodes.inference, name, data)
            except NodeError as exc:
                await ws.close(code=1011 if exc.status >= 500 else 1007, message=str(exc)[:120].encode())
                break
            if not isinstance(result, dict):
                async for piece in iterate_in_thread(result):
                    await ws.send_str(piece)
                await ws.send_str(STREAM_END)
                continue
            output = result["output"]
            if isinstance(output, str):
                await ws.send_str(output)
            elif isinstance(output, bytes):
                await ws.send_bytes(output)
            else:
                await ws.send_bytes(msgpack.packb(output))
        return ws

    app.router.add_get("/", about)
    app.router.add_post("/add_node", add_node)
    app.router.add_post("/remove_node", remove_node)
    app.router.add_post("/{node}/initialize", initialize)
    app.router.add_post("/{node}/inference", inference)
    app.router.add_get("/{node}/get_status", get_status)
    app.router.add_get("/{node}/ws_inference", ws_inference)
