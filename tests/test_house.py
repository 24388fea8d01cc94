"""The house rules of issue #29 item 4, measured from the source by ``bench.house``: no
module import cycle (imports inside functions count: grimp's graph), no ``tomllib`` outside
``vasim.core.config`` (the one TOML reader), no private name (``_x``) imported from another
package of vasim; and no module over 800 lines (the first house step's rule). ``python -m
bench.house`` prints the lists when this fails."""

from __future__ import annotations

from bench.house import measure


def test_no_module_cycle_tomllib_or_private_import_across_packages() -> None:
    facts = measure()
    assert facts.cycles == [], "module cycles (move the shared piece down): " + "; ".join(
        facts.cycles)
    assert facts.tomllib_outside == [], "tomllib outside vasim.core.config (use parse_toml)"
    assert facts.private_imports == [], "private names imported across packages"
    assert facts.long_modules == [], "modules over 800 lines (split them)"
