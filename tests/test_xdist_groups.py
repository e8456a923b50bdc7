"""`make test` runs the suite on two xdist workers with `--dist loadgroup`: the tests of one `xdist_group` share
drives or a sweep and must run in one process. xdist's scheduler groups by the node id it rewrote to end in
`@<group>`; pytest 9.2 stopped showing that rewrite (the group's tests were then split across workers and simulated
their drives twice), hence the pin in pyproject.toml. This fails if a new pytest or xdist breaks it again."""
from __future__ import annotations

import os

import pytest


@pytest.mark.xdist_group("probe")
def test_a_grouped_test_carries_its_group_in_the_node_id(request):
    if not os.environ.get("PYTEST_XDIST_WORKER"):
        pytest.skip("not run on xdist workers")
    assert request.node.nodeid.endswith("@probe"), request.node.nodeid
