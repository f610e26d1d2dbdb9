#!/usr/bin/env python3
"""executable.py of the extending page (step 5), the spec's code with its import changed. EMOS
does not need it (the launcher forks component processes from the recipe), but it works: run
``python -m my_awesome_pkg.executable --component_type AwesomeComponent`` to start one
component under EMOS (emos/entrypoint.py)."""
from emos import executable_main
from my_awesome_pkg.awesome_component import AwesomeComponent, AwesomeConfig

# Create lists of available components/config classes
_components_list = [AwesomeComponent]
_configs_list = [AwesomeConfig]


# Create entry point main
def main(args=None):
    executable_main(list_of_components=_components_list, list_of_configs=_configs_list)


if __name__ == "__main__":
    main()
