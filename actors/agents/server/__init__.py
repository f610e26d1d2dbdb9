"""Local model server for development and tests: ``emos serve models``.

A stand-in, not a production inference server. It speaks the OpenAI API (chat with SSE
streaming and tool calls, embeddings, speech, transcription), the Ollama API (chat with NDJSON
streaming, tags, show, pull, embed, generate) and RoboML's node protocol (HTTP, WebSocket and
RESP), backed by models that run offline here: a deterministic scripted chat responder (or a
GGUF model through llama.cpp), the packaged all-MiniLM-L6-v2 embedder, espeak-ng speech and
OpenCV's people detector. It binds 127.0.0.1 by default, starts in well under a second (models
load on first use) and exits cleanly on SIGTERM, because the chaos suite kills and restarts it.
"""
