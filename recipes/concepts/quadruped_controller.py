"""quadruped_controller.py of the events-and-actions page (concepts/events-and-actions.md,
"Automatic Adaptation (Terrain Switching)"): the page's component, with its import changed.
The recipe that uses it is quadruped_controller_recipe.py beside it."""
from typing import Literal

from emos import BaseComponent


class QuadrupedController(BaseComponent):
    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        # Some logic

    def switch_gait_controller(self, controller_type: Literal['stairs', 'sand', 'snow', 'gravel']):
        self.get_logger().info("New terrain detected! Switching gait.")
        # Logic to change controller parameters... (the page leaves it out; here it says which)
        self.get_logger().info(f"Gait controller: {controller_type}")
