"""What the benchmarks' peer tests share: an environment in which the package registry cannot
be reached, so that installing a peer fails the way it does on a machine without network."""
from __future__ import annotations

import os
from pathlib import Path

from emos.tools.bench import peer_env


def unreachable_registry_env(tmp_path: Path) -> dict[str, str]:
    """os.environ with an empty peer folder under ``tmp_path`` and pip pointed at a closed port
    (no retries, no cache, no local wheels, no constraints)."""
    env = dict(os.environ)
    env.update({peer_env.ENV_PEER_DIR: str(tmp_path / "peers"), "PIP_CONFIG_FILE": os.devnull,
                "PIP_INDEX_URL": "http://127.0.0.1:9/simple", "PIP_EXTRA_INDEX_URL": "", "PIP_FIND_LINKS": str(tmp_path),
                "PIP_RETRIES": "0", "PIP_TIMEOUT": "3", "PIP_NO_CACHE_DIR": "1"})
    env.pop("PIP_CONSTRAINT", None)
    return env
