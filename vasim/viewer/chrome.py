"""viser's own controls, removed from the trainee's page (issue #26.1).

viser's client puts its own chrome around the GUI: a "Configuration & diagnostics" button
that opens the server's address, Dev Settings and a scene tree with show/hide (eye) and
edit (pencil) toggles for every node, plus a Share button and a command palette button.
On the trainee's page any of these lets a subject change their own condition (one click
hid the whole path, unrecorded). They are all client-side: nothing reaches the server, so
the server cannot refuse them; they are taken off the page instead:

* ``configure_theme(show_share_button=False, show_logo=False)`` (viser's public theme API);
* a style sheet delivered as the first element of the page's GUI (``gui.add_html``: an
  HTML element's ``<style>`` applies to the whole page, and it arrives with the page's first
  GUI messages, before anything can be clicked) hides the settings toggle, the share and
  command buttons and the whole configuration panel (server address, buttons, scene tree).
  The selectors name the icons viser 1.1.1 draws (Tabler's ``tabler-icon-<name>``
  classes); ``tests/browser/test_chrome_browser.py`` proves in Chromium that none of the
  controls is visible or reachable.

The **experimenter's** page keeps its configuration panel (**decision**): it is another
server with its own scene, so its eye/pencil toggles change only the experimenter's own
third-person view, never the trainee's; only its Share button goes (sharing is refused by
:mod:`vasim.viewer.isolation` anyway).

A page that needs to trust the trainee's browser cannot (a subject with developer tools can
restyle anything); these measures stop ordinary clicks, and the server side
(:mod:`vasim.viewer.isolation`) stops crafted messages.
"""

from __future__ import annotations

import viser

HIDDEN_ICONS = ("adjustments", "arrow-back", "share", "list-search")
"""Tabler icons of viser's chrome buttons: settings toggle (and its way back), share,
command palette."""

TRAINEE_CSS = "\n".join([
    "/* vasim: viser's own controls are not part of the trainee's page (issue #26.1) */",
    ",\n".join([*(f".mantine-ActionIcon-root:has(.tabler-icon-{i})" for i in HIDDEN_ICONS),
                # The configuration panel: server address, Dev Settings, the scene tree.
                ".mantine-Stack-root:has(.tabler-icon-home-move)",
                ".mantine-Stack-root:has(.tabler-icon-pencil)"])
    + " { display: none !important; }",
])


def lock_trainee_chrome(server: viser.ViserServer) -> None:
    """Removes viser's own controls from ``server``'s pages (call before other GUI)."""
    server.gui.configure_theme(control_width="medium", show_logo=False,
                               show_share_button=False)
    server.gui.add_html(f"<style>{TRAINEE_CSS}</style>")


def experimenter_chrome(server: viser.ViserServer) -> None:
    """The experimenter's page: wide panel, no Share button (see the module doc)."""
    server.gui.configure_theme(control_width="large", show_share_button=False)


__all__ = ["HIDDEN_ICONS", "TRAINEE_CSS", "experimenter_chrome", "lock_trainee_chrome"]
