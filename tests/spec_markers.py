"""Collects which tests pin which spec ID (the @pytest.mark.spec(...) markers)."""

import re


def marked_tests(items):
    """Map spec ID -> sorted list of test node ids (parametrisation stripped)."""
    table = {}
    for item in items:
        for mark in item.iter_markers(name="spec"):
            for spec_id in mark.args:
                node = re.sub(r"\[.*\]$", "", item.nodeid)
                table.setdefault(spec_id, set()).add(node)
    return {k: sorted(v) for k, v in table.items()}
