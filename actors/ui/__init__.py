"""The recipe's web UI: a component that serves a page for monitoring, configuration and control.

``launcher.enable_ui(inputs=[...], outputs=[...])`` adds a :class:`UIComponent` in its own
supervised process. Every asset it serves ships in this package (no CDN, nothing downloaded at
run time), so the page works on a robot without internet.
"""
from emos.actors.ui.component import UIComponent
from emos.actors.ui.config import UIConfig

__all__ = ["UIComponent", "UIConfig"]
