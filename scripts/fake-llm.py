#!/usr/bin/env python3
"""A loopback OpenAI chat-completions endpoint for demonstrations: answers every question with a
percentage derived from a hash of the prompt (deterministic, so shards asking the same question
get the same answer), and counts requests on stderr. Usage: scripts/fake-llm.py PORT"""

import hashlib
import http.server
import json
import sys

count = 0


class H(http.server.BaseHTTPRequestHandler):
    def do_POST(self):
        global count
        body = json.loads(self.rfile.read(int(self.headers["Content-Length"])))
        text = json.dumps(body["messages"])
        count += 1
        pct = 1 + int(hashlib.sha256(text.encode()).hexdigest(), 16) % 100
        out = json.dumps(
            {
                "id": "x",
                "object": "chat.completion",
                "created": 0,
                "model": body["model"],
                "choices": [
                    {
                        "index": 0,
                        "finish_reason": "stop",
                        "message": {"role": "assistant", "content": f"{pct}%"},
                    }
                ],
                "usage": {"prompt_tokens": 10, "completion_tokens": 2, "total_tokens": 12},
            }
        ).encode()
        self.send_response(200)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(out)))
        self.end_headers()
        self.wfile.write(out)
        sys.stderr.write(f"requests {count}\n")

    def log_message(self, *a):
        pass


http.server.ThreadingHTTPServer(("127.0.0.1", int(sys.argv[1])), H).serve_forever()
