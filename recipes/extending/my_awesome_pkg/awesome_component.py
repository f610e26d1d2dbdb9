"""awesome_component.py of the extending page (advanced/extending.md, steps 3 and 4): a custom
configuration and a custom component. The spec's code with its imports changed, and
``Optional``/``Sequence`` imported (errata: the page uses them without importing them)."""
from collections.abc import Sequence  # errata: not imported on the page

from attrs import define, field

from emos import BaseComponent, BaseComponentConfig, ComponentFallbacks, Topic, base_validators  # noqa: F401 - the page imports ComponentFallbacks


@define(kw_only=True)
class AwesomeConfig(BaseComponentConfig):
    """
    Component configuration parameters
    """

    extra_float: float = field(
        default=10.0, validator=base_validators.in_range(min_value=1e-9, max_value=1e9)
    )
    extra_flag: bool = field(default=True)


class AwesomeComponent(BaseComponent):
    def __init__(
        self,
        *,
        component_name: str,
        inputs: Sequence[Topic] | None = None,
        outputs: Sequence[Topic] | None = None,
        config_file: str | None = None,
        config: AwesomeConfig | None = None,
        **kwargs,
    ) -> None:
        # Set default config if config is not provided
        self.config: AwesomeConfig = config or AwesomeConfig()
        super().__init__(
            component_name=component_name,
            inputs=inputs,
            outputs=outputs,
            config=self.config,
            config_file=config_file,
            **kwargs,
        )

    def _execution_step(self):
        """
        The execution step is the main (timed) functional unit in the component.
        Gets called automatically at every loop step (with a frequency of
        'self.config.loop_rate').
        """
        super()._execution_step()
        # Add your main execution step here
