#!/usr/bin/env python3
"""Opens URL in headless Chromium and prints the value of an attribute of the page's body element
once the page has set it (polled over the DevTools protocol on --remote-debugging-pipe, Python's
standard library only). For measurements that take real time, which a --dump-dom would not wait
for: scripts/player-fps reads the report player's playback frame rate with it.

usage: chromium-wait-attribute.py URL ATTRIBUTE [TIMEOUT_S]   (CHROMIUM=path overrides
/usr/bin/chromium)
"""
import json
import os
import subprocess
import sys
import tempfile
import time


def main():
    url, attribute = sys.argv[1], sys.argv[2]
    timeout_s = float(sys.argv[3]) if len(sys.argv) > 3 else 30.0
    chromium = os.environ.get("CHROMIUM", "/usr/bin/chromium")
    to_browser_r, to_browser_w = os.pipe()
    from_browser_r, from_browser_w = os.pipe()

    def pipes_as_fd_3_and_4():
        a, b = os.dup(to_browser_r), os.dup(from_browser_w)
        os.dup2(a, 3)
        os.dup2(b, 4)
        os.set_inheritable(3, True)
        os.set_inheritable(4, True)

    with tempfile.TemporaryDirectory() as profile:
        browser = subprocess.Popen(
            [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
             "--disable-background-networking", "--window-size=1300,900",
             f"--user-data-dir={profile}", "--remote-debugging-pipe", "about:blank"],
            close_fds=False, preexec_fn=pipes_as_fd_3_and_4,
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        os.close(to_browser_r)
        os.close(from_browser_w)
        send = os.fdopen(to_browser_w, "wb", buffering=0)
        receive = os.fdopen(from_browser_r, "rb", buffering=0)
        pending = b""
        next_id = 0

        def call(method, params=None, session=None):
            nonlocal pending, next_id
            next_id += 1
            message = {"id": next_id, "method": method, "params": params or {}}
            if session:
                message["sessionId"] = session
            send.write(json.dumps(message).encode() + b"\0")
            while True:
                while b"\0" not in pending:
                    chunk = receive.read(65536)
                    if not chunk:
                        sys.exit(f"Chromium closed the DevTools pipe during {method}")
                    pending += chunk
                raw, pending = pending.split(b"\0", 1)
                reply = json.loads(raw)
                if reply.get("id") == next_id:
                    if "error" in reply:
                        sys.exit(f"{method}: {reply['error']}")
                    return reply["result"]

        try:
            target = call("Target.createTarget", {"url": url})["targetId"]
            session = call("Target.attachToTarget",
                           {"targetId": target, "flatten": True})["sessionId"]
            expression = f"document.body && document.body.getAttribute({json.dumps(attribute)})"
            deadline = time.monotonic() + timeout_s
            while time.monotonic() < deadline:
                time.sleep(0.2)
                result = call("Runtime.evaluate",
                              {"expression": expression, "returnByValue": True}, session)
                value = result["result"].get("value")
                if value:
                    print(value)
                    return
            sys.exit(f"the page set no {attribute} within {timeout_s} s")
        finally:
            try:
                call("Browser.close")
            except SystemExit:
                pass
            browser.wait(timeout=10)


if __name__ == "__main__":
    main()
