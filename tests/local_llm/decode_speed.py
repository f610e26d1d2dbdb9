"""Decode speed of the packaged SmolLM2 in this process, under the OpenMP settings of the
environment (docs/local-models.md, "One thread by default"). Not a test: a measurement to run
several times with settings alternated, e.g.

    NT=1 python3 tests/local_llm/decode_speed.py 4
    NT=2 OMP_WAIT_POLICY=PASSIVE python3 tests/local_llm/decode_speed.py 4
    NT=2 OMP_WAIT_POLICY=PASSIVE GOMP_SPINCOUNT=10000 python3 tests/local_llm/decode_speed.py 4

prints the tokens per second after the first token of each answer (48 tokens, temperature 0)."""
from __future__ import annotations

import json
import os
import sys
import time

from emos.actors.agents.server.gguf import packaged_smollm2
from emos.actors.agents.server.llama_backend import _import_llama


def main(answers: int) -> None:
    threads = int(os.environ.get("NT", "1"))
    llm = _import_llama()(model_path=str(packaged_smollm2()), n_threads=threads, n_ctx=512, verbose=False, seed=1)
    rates = []
    for _ in range(answers):
        first, tokens = None, 0
        for _chunk in llm.create_chat_completion(messages=[{"role": "user", "content": "Write a short story about a robot in a kitchen."}],
                                                 max_tokens=48, temperature=0.0, stream=True):
            first = time.perf_counter() if first is None else first
            tokens += 1
        rates.append((tokens - 1) / (time.perf_counter() - first))
    print(json.dumps({"threads": threads, "omp_wait_policy": os.environ.get("OMP_WAIT_POLICY"), "gomp_spincount": os.environ.get("GOMP_SPINCOUNT"),
                      "load_1min": round(os.getloadavg()[0], 2), "tokens_per_s": sorted(round(r, 1) for r in rates)}))


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 4)
