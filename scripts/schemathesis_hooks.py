"""Schemathesis hooks of scripts/schemathesis.sh.

A `request_id` is an idempotency key: the server answers a key it has seen with the stored reply,
and refuses a key used before with another body (422), as the IETF Idempotency-Key draft says.
Generated cases reuse short keys such as "0" for unrelated bodies, which would turn schema-valid
requests into refusals, so every valid key (in the body, or in the `Idempotency-Key` header) is
given a fresh value before it is sent. Retries and
reuse of keys are tested by the server's own suites.
"""

import uuid

import schemathesis


@schemathesis.hook
def before_call(context, case, kwargs):
    fresh = uuid.uuid4().hex
    body = case.body
    if isinstance(body, dict):
        key = body.get("request_id")
        if isinstance(key, str) and 1 <= len(key) <= 200:
            body["request_id"] = fresh
    # The `Idempotency-Key` header is the same key: fresh too, and equal to the body's when both
    # are sent (different ones are a 400 by design).
    headers = case.headers or {}
    for name in [h for h in headers if h.lower() == "idempotency-key"]:
        headers[name] = fresh
        if isinstance(body, dict) and "request_id" in body:
            body["request_id"] = fresh
