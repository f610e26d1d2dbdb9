"""Services created when a component configures are in the derived policy, read from the code
without configuring anything: constant names, f-strings of the component's name, loops over
literal lists, a mixin's helper with a local variable, a class constant, a branch; a name only
the running component knows is reported (file:line) and can be declared with
``declared_services``; ``action_servers()`` covers the action servers it lists."""
from __future__ import annotations

import pytest

from emos.security.policy import Roles, access_control, derive_permissions, render_json5
from emos.security.recipe_graph import load_recipe_graph

pytestmark = pytest.mark.unit

RECIPE = '''
import os
from emos import BaseComponent, Launcher, Topic
from emos.msgs import TriggerRequest, TriggerResponse

MARK = os.environ["CONFIGURE_MARK"]


def made_up_name():
    return "only/known/at/run/time"


class Helpers:
    def make_path_services(self):
        name = self.component_name
        self.create_service(f"{name}/save_path", TriggerRequest, TriggerResponse, self.answer)


class Busy(Helpers, BaseComponent):
    SERVICE = "beacon/ping"

    def custom_on_configure(self):
        open(MARK, "w").write("configured")  # must never run while deriving a policy
        self.create_service("lamp/set", TriggerRequest, TriggerResponse, self.answer)
        self.create_service(f"{self.component_name}/reset", TriggerRequest, TriggerResponse, self.answer)
        for verb in ("forward", "backward"):
            self.create_service(f"{self.component_name}/move_{verb}", TriggerRequest, TriggerResponse, self.answer)
        self.create_service(self.SERVICE, TriggerRequest, TriggerResponse, self.answer)
        if self.config.visualization:
            self.create_service(self.component_name + "/debug", TriggerRequest, TriggerResponse, self.answer)
        self.make_path_services()

    def answer(self, request):
        return TriggerResponse(success=True)


class Opaque(BaseComponent):
    declared_services = ["opaque/declared"]

    def custom_on_configure(self):
        self.create_service(made_up_name(), TriggerRequest, TriggerResponse, lambda r: TriggerResponse())


busy = Busy(component_name="busy", outputs=[Topic(name="beat", msg_type="String")])
opaque = Opaque(component_name="opaque", inputs=[Topic(name="beat", msg_type="String")])
launcher = Launcher()
launcher.add_pkg(components=[busy, opaque])
launcher.bringup()
'''


def test_configure_time_services_are_in_the_policy(tmp_path, monkeypatch):
    recipe, mark = tmp_path / "configure_recipe.py", tmp_path / "configured"
    recipe.write_text(RECIPE)
    monkeypatch.setenv("CONFIGURE_MARK", str(mark))
    graph = load_recipe_graph(recipe)
    assert not mark.exists()  # nothing was configured
    busy = next(c for c in graph.components if c.name == "busy")
    assert busy.services == sorted(["lamp/set", "busy/reset", "busy/move_forward", "busy/move_backward", "beacon/ping", "busy/debug",
                                    "busy/save_path"]), busy.services
    opaque = next(c for c in graph.components if c.name == "opaque")
    assert opaque.services == ["opaque/declared"]
    assert len(graph.notes) == 1 and "component 'opaque' (Opaque)" in graph.notes[0] and "configure_recipe.py:" in graph.notes[0]
    assert "made_up_name()" in graph.notes[0] and "declared_services" in graph.notes[0], graph.notes

    roles = Roles(robots=["robot1"], operators=["alice"], viewers=["bob"])
    perms = derive_permissions(graph, roles)
    assert "busy/move_forward" in perms["robot1"]["serve"] and "lamp/set" in perms["alice"]["call"] and perms["bob"]["call"] == []
    acl = access_control(graph, roles, "lab")
    serve = next(r for r in acl["rules"] if r["id"] == "robot1: serves its services (ingress)")
    call = next(r for r in acl["rules"] if r["id"] == "alice: calls services (ingress)")
    for key in ("emos/lab/_srv_/lamp/set", "emos/lab/_srv_/busy/save_path", "emos/lab/_srv_/beacon/ping"):
        assert key in serve["key_exprs"] and key in call["key_exprs"], key
    text = render_json5({"access_control": acl}, graph, roles, "alice", "lab")
    assert "// NOT DERIVED: component 'opaque'" in text


def test_a_real_recipes_configure_time_services():
    """point_navigation: the planner's path files, the drive manager's maneuvers, the map
    server's save_map, the localizer's global localization; the controller's vision action is
    declared by its action_servers(), so nothing is left unknown."""
    graph = load_recipe_graph("recipes/point_navigation.py")
    for name in ("planner/save_plan_to_file", "planner/start_path_recording", "drive_manager/move_to_unblock",
                 "global_map_server/save_map", "localizer/global_localization", "mapper/clear_entirely_local_costmap"):
        assert name in graph.services, (name, graph.services)
    assert graph.notes == []
