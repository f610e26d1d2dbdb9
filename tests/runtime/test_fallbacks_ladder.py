"""The fallback state machine and the recipe-facing fallback and action API, without processes."""
import pytest

from emos import Action, BaseComponent, Topic
from emos.actions import log, publish_message, restart, update_parameter
from emos.core.fallbacks import Fallback, FallbackTracker, component_fallback
from emos.core.health import HealthLevel
from emos.events.action import decode_value, encode_value, resolve_bindings
from emos.msgs import Float32, String

pytestmark = pytest.mark.unit

C, A, S, H = HealthLevel.COMPONENT_FAILURE, HealthLevel.ALGORITHM_FAILURE, HealthLevel.SYSTEM_FAILURE, HealthLevel.HEALTHY


def names(comp, n):
    return [Action(getattr(comp, f"m{i}")) for i in range(n)]


class Comp(BaseComponent):
    def m0(self):
        return False

    def m1(self):
        return False

    def m2(self):
        return False


def run_ladder(tracker, level, max_steps=50):
    """Feed a persistent failure and collect what the tracker does, one attempt per period."""
    done, t = [], 0.0
    for _ in range(max_steps):
        tracker.observe(level, now=t)
        d = tracker.next(now=t)
        if d is not None:
            done.append("giveup" if d["kind"] == "giveup" else d["action"].method_name)
            if d["kind"] == "giveup":
                break
        t += tracker.period
    return done


def test_a_ladder_runs_each_step_exactly_max_retries_times_then_gives_up():
    comp = Comp(component_name="c")
    tr = FallbackTracker({"on_algorithm_fail": Fallback(names(comp, 3), max_retries=2)}, None, None, rate=10.0)
    assert run_ladder(tr, A) == ["m0", "m0", "m1", "m1", "m2", "m2", "giveup"]
    assert tr.gave_up and tr.next(now=100.0) is None  # nothing more until it recovers


def test_max_retries_none_is_unlimited_for_one_action_and_once_per_step_for_a_list():
    comp = Comp(component_name="c")
    single = FallbackTracker({"on_component_fail": Fallback(Action(comp.m0))}, None, None, rate=10.0)
    assert run_ladder(single, C, max_steps=30) == ["m0"] * 30
    ladder = FallbackTracker({"on_component_fail": Fallback(names(comp, 2))}, None, None, rate=10.0)
    assert run_ladder(ladder, C) == ["m0", "m1", "giveup"]


def test_fallback_rate_limits_attempts():
    comp = Comp(component_name="c")
    tr = FallbackTracker({"on_fail": Fallback(Action(comp.m0))}, None, None, rate=2.0)
    tr.observe(C, now=0.0)
    assert tr.next(now=0.0) is not None
    assert tr.next(now=0.3) is None and tr.wait_s(now=0.3) == pytest.approx(0.2)
    assert tr.next(now=0.5) is not None


def test_budgets_reset_only_after_staying_healthy_for_reset_after():
    comp = Comp(component_name="c")
    tr = FallbackTracker({"on_component_fail": Fallback(Action(comp.m0), max_retries=1)}, None, None, rate=10.0, reset_after=5.0)
    tr.observe(C, now=0.0)
    assert tr.next(now=0.0)["kind"] == "action"
    tr.observe(H, now=1.0)
    tr.observe(H, now=3.0)  # healthy, but not long enough
    tr.observe(C, now=3.5)
    assert tr.next(now=3.5)["kind"] == "giveup"
    tr.observe(H, now=4.0)
    tr.observe(H, now=9.5)  # healthy for 5.5 s: budget and give-up reset
    assert not tr.gave_up
    tr.observe(C, now=10.0)
    assert tr.next(now=10.0)["kind"] == "action"


def test_handler_priority_specific_then_catch_all_then_default_for_component_failure_only():
    comp = Comp(component_name="c")
    default = Fallback(restart(component=comp))
    tr = FallbackTracker({"on_system_fail": Fallback(Action(comp.m1)), "on_fail": Fallback(Action(comp.m2))}, None, default, rate=10.0)
    assert tr.handler_for(S)[0] == "on_system_fail"
    assert tr.handler_for(A)[0] == "on_fail"
    assert tr.handler_for(C)[0] == "on_fail"
    bare = FallbackTracker({}, None, default, rate=10.0, default_after=0.25)
    assert bare.handler_for(C)[0] == "default" and bare.handler_for(A) is None and bare.handler_for(S) is None
    bare.observe(C, now=0.0)
    assert bare.next(now=0.1) is None  # the default waits until the failure has lasted default_after
    assert bare.next(now=0.3)["action"].kind == "lifecycle"


def test_giveup_runs_the_on_giveup_actions():
    comp = Comp(component_name="c")
    comp.on_component_fail(action=Action(comp.m0), max_retries=1)
    comp.on_giveup(fallback=log(msg="gave up"))
    fb = comp.fallbacks
    tr = FallbackTracker({"on_component_fail": fb["on_component_fail"]}, fb["on_giveup"], None, rate=10.0)
    tr.observe(C, now=0.0)
    tr.next(now=0.0)
    d = tr.next(now=1.0)
    assert d["kind"] == "giveup" and d["actions"][0].predefined == "log"


def test_recipe_api_checks_arguments():
    comp = Comp(component_name="c")
    with pytest.raises(TypeError, match="Actions"):
        comp.on_fail(action=comp.m0)
    with pytest.raises(ValueError, match="max_retries"):
        comp.on_fail(action=Action(comp.m0), max_retries=0)
    with pytest.raises(TypeError, match="not both"):
        comp.on_fail(action=Action(comp.m0), fallback=Action(comp.m1))
    with pytest.raises(AttributeError, match="no parameter"):
        update_parameter(component=comp, param_name="loop_rat", new_value=1.0)
    with pytest.raises(TypeError, match="keyword|positional"):
        restart(comp)  # keyword-only, as in the spec
    t = Topic(name="x", msg_type="String")
    with pytest.raises(TypeError, match="String"):
        publish_message(topic=t, msg=Float32(data=1.0))


def test_action_targets_are_classified():
    comp = Comp(component_name="c")
    assert Action(comp.m0).kind == "component" and Action(comp.m0).component == "c"
    assert Action(comp.restart).kind == "lifecycle" and restart(component=comp).kind == "lifecycle"
    assert Action(print).kind == "function"
    assert log(msg="x").kind == "predefined"


def test_bindings_resolve_at_fire_time_and_cross_processes_as_plain_data():
    cmd = Topic(name="cmd", msg_type="String")
    battery = Topic(name="battery", msg_type="Float32")
    a = Action(print, args=(cmd.msg.data, battery), kwargs={"k": [battery.msg.data]})
    assert set(a.bound_topics) == {"/cmd", "/battery"}
    latest = {"/cmd": String(data="kitchen"), "/battery": Float32(data=3.0)}
    args = resolve_bindings(a.args, latest.get)
    assert args[0] == "kitchen" and args[1] == Float32(data=3.0)
    assert resolve_bindings(a.kwargs, latest.get) == {"k": [3.0]}
    assert resolve_bindings(a.args, {}.get) == (None, None)
    wire = encode_value(list(args) + [HealthLevel.COMPONENT_FAILURE], "test")
    back = decode_value(wire)
    assert back[0] == "kitchen" and back[1] == Float32(data=3.0) and back[2] is HealthLevel.COMPONENT_FAILURE


def test_component_fallback_runs_only_when_configured():
    class Driver(BaseComponent):
        @component_fallback
        def reconnect(self):
            return True

    d = Driver(component_name="d")
    assert d.reconnect() is False  # not running: skipped, reported as not recovered


def test_launcher_wide_policies_fill_only_what_a_component_left_open():
    from emos.supervisor.orchestration import Orchestration, check_policy

    own = Comp(component_name="own")
    own.on_algorithm_fail(action=Action(own.m1))
    catch_all = Comp(component_name="catch_all")
    catch_all.on_fail(action=Action(catch_all.m2))
    bare = Comp(component_name="bare")
    orch = Orchestration(policies={"on_fail": check_policy("on_fail", "restart", None),
                                   "on_system_fail": check_policy("on_system_fail", "m0", 2)})
    h = orch.handlers_for(own)
    assert h["on_algorithm_fail"].steps[0].method_name == "m1"  # its own
    assert h["on_component_fail"].steps[0].kind == "lifecycle"  # launcher on_fail: restart
    assert h["on_system_fail"].steps[0].method_name == "m0" and h["on_system_fail"].max_retries == 2
    assert set(orch.handlers_for(catch_all)) == {"on_fail"}  # its own catch-all wins everywhere
    assert orch.handlers_for(bare)["on_component_fail"].steps[0].component == "bare"
    with pytest.raises(ValueError, match="no public method 'nope'"):
        Orchestration(policies={"on_fail": check_policy("on_fail", "nope", None)}).check([bare])
    with pytest.raises(ValueError, match="max_retries"):
        check_policy("on_fail", "restart", 0)


def test_an_overridden_stop_is_a_component_method_but_actions_stop_is_lifecycle():
    class DriveManager(BaseComponent):
        def stop(self):
            return "brake"

    d = DriveManager(component_name="d")
    assert Action(d.stop).kind == "component"
    from emos.actions import stop

    assert stop(component=d).kind == "lifecycle"
