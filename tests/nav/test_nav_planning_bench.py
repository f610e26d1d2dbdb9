"""The planning table that ``emos bench nav`` embeds."""
import pytest

from emos.tools.bench.nav_planning import format_table, run_planning_table

pytestmark = pytest.mark.unit


def test_planning_table_rows_have_the_contract_keys():
    # Both stop at their first solution; the budget only bounds a loaded machine.
    rows = run_planning_table(budget_s=3.0, planners=["ompl.geometric.RRTConnect", "KPIECE1"])
    assert [r["planner"] for r in rows] == ["RRTConnect", "KPIECE1"]
    for r in rows:
        assert set(r) == {"planner", "solved", "time_s", "length_m", "simplification_time_s"}
        assert r["solved"] is True
        assert 0 < r["time_s"] <= 3.0 + 0.2
        assert r["length_m"] > 9.0  # the query crosses two doorways
    table = format_table(rows)
    assert "| RRTConnect | True |" in table
