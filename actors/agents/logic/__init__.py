"""Intelligence logic as small pure pieces: prompts, history, RAG, tools, streaming,
preprocessors, detections as text, VLM output parsing, semantic routing and map encoding.

Nothing here starts a process or touches a topic; components wire these pieces to topics.
"""
