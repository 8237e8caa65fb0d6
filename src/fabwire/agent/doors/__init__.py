"""Doors: the REST dialects other tools already speak (OctoPrint, Moonraker), as thin translations of one model
(`fabwire.agent.model` machines, `fabwire.agent.library` files and queues, the agent's jobs).

Every machine is served under its own prefix, `/printers/NAME/…`, and the default machine (the first da Vinci,
else the first Line-us) at the root as well.
"""

from __future__ import annotations

from fastapi import FastAPI
from starlette.datastructures import UploadFile
from starlette.requests import HTTPConnection

from fabwire.agent.core import Agent
from fabwire.agent.model import MachineView, TakesNoJobs

JSON_BODY: dict[str, object] = {"requestBody": {"required": False, "content": {"application/json": {}}}}
"""The body a door's command route declares (`fabwire.agent.boundary` refuses undeclared bodies)."""
MULTIPART_BODY: dict[str, object] = {"requestBody": {"required": True, "content": {"multipart/form-data": {}}}}
"""The body an upload route declares: the form slicers send, its file part streamed by the door."""

PREFIXES = ("", "/printers/{machine}")
"""Where each door's routes are mounted: the default machine at the root, every machine by name."""


def machine_of(agent: Agent, request: HTTPConnection) -> MachineView:
    """The machine a request addresses (by its prefix), or the default one at the root."""
    name = request.path_params.get("machine")
    if name is not None:
        return agent.library.machines.view(name)
    view = agent.library.machines.default()
    if view is None:
        raise TakesNoJobs("this agent monitors no printer or drawing machine: address one as /printers/NAME/")
    return view


def file_name(upload: UploadFile) -> str:
    """The name of an uploaded file part without any folders a client put in it (Windows' too): the folder
    is the form's `path` field."""
    return (upload.filename or "").replace("\\", "/").rsplit("/", 1)[-1]


def base_url(request: HTTPConnection) -> str:
    """The URL the request's door lives at (with its machine prefix), without a trailing slash."""
    name = request.path_params.get("machine")
    root = str(request.base_url).rstrip("/")
    return f"{root}/printers/{name}" if name is not None else root


def mount_doors(app: FastAPI, agent: Agent) -> None:
    """Add the library routes, the OctoPrint- and the Moonraker-compatible doors to the agent's app."""
    from fabwire.agent.appkeys import AppKeys
    from fabwire.agent.doors import library_api, moonraker, octoprint

    appkeys = AppKeys(agent.state_dir)
    library_api.mount(app, agent, appkeys)
    octoprint.mount(app, agent, appkeys)
    moonraker.mount(app, agent)
