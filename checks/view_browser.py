"""Drives /view/ in headless Chromium over the DevTools protocol (see view_browser.sh)."""
import json, os, subprocess, sys, tempfile, time, urllib.request
import websocket

BIN = sys.argv[1]
HTTP, GRPC, CDP = 18093, 15093, 9339
KEY = "view-check-key-0123456789"
BASE = f"http://127.0.0.1:{HTTP}"
HERE = os.path.dirname(os.path.abspath(__file__))


def call(method, path, body=None):
    req = urllib.request.Request(BASE + path, method=method, data=None if body is None else json.dumps(body).encode(),
                                 headers={"content-type": "application/json", "authorization": f"Bearer {KEY}"})
    with urllib.request.urlopen(req, timeout=30) as r:
        raw = r.read()
        return json.loads(raw) if raw else None


def wait_for(f, what, timeout=30):
    t0 = time.time()
    while time.time() - t0 < timeout:
        v = f()
        if v:
            return v
        time.sleep(0.2)
    raise SystemExit(f"FAIL: timed out waiting for {what}")


class Page:
    def __init__(self, ws_url):
        self.ws = websocket.create_connection(ws_url, timeout=30)
        self.n = 0

    def send(self, method, **params):
        self.n += 1
        self.ws.send(json.dumps({"id": self.n, "method": method, "params": params}))
        while True:
            m = json.loads(self.ws.recv())
            if m.get("id") == self.n:
                if "error" in m:
                    raise SystemExit(f"FAIL: {method}: {m['error']}")
                return m.get("result", {})

    def eval(self, expr):
        r = self.send("Runtime.evaluate", expression=expr, returnByValue=True)
        if "exceptionDetails" in r:
            raise SystemExit(f"FAIL: page error in {expr!r}: {r['exceptionDetails']}")
        return r["result"].get("value")


def main():
    env = dict(os.environ, FUSION_API_KEYS=f"{KEY}=acme")
    server = subprocess.Popen([BIN, "--http-addr", f"127.0.0.1:{HTTP}", "--grpc-addr", f"127.0.0.1:{GRPC}"],
                              env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    profile = tempfile.mkdtemp()
    browser = None
    try:
        wait_for(lambda: ok(f"{BASE}/healthz"), "the server")
        scene = json.load(open(os.path.join(HERE, "../tests/fixtures/cat062/service_seed001.json")))["request"]
        created = call("POST", "/v1/sessions", {"kind": "plot_fusion", "origin": scene["origin"], "radars": scene["radars"]})
        sid = created["id"]
        browser = subprocess.Popen(["chromium", "--headless=new", "--no-sandbox", "--disable-gpu",
                                    f"--remote-debugging-port={CDP}", f"--user-data-dir={profile}",
                                    "--window-size=1400,900", "about:blank"],
                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        targets = wait_for(lambda: page_targets(), "Chromium's DevTools")
        page = Page(targets[0]["webSocketDebuggerUrl"])
        page.send("Page.enable")
        page.send("Runtime.enable")
        page.send("Page.navigate", url=f"{BASE}/view/#session={sid}")
        wait_for(lambda: page.eval("typeof window.viewState === 'object'"), "the page")
        # The key, entered as a user does: typed and saved.
        page.eval(f"document.getElementById('key').value = {json.dumps(KEY)}; document.getElementById('save').click(); true")
        wait_for(lambda: page.eval(f"viewState.session === {json.dumps(sid)} && viewState.snapshots > 0"),
                 "the page's first snapshot")
        plots = sorted(scene["plots"], key=lambda p: p["t"])
        n = 6
        size = -(-len(plots) // n)
        for k in range(n):
            call("POST", f"/v1/sessions/{sid}/batches",
                 {"sequence": k + 1, "plots": plots[k * size:(k + 1) * size], "flush": k == n - 1})
            time.sleep(0.3)
        state = call("GET", f"/v1/sessions/{sid}")
        want = sorted(t["id"] for t in state["plot_fusion"]["tracks"] if t["status"] == "confirmed")
        wait_for(lambda: page.eval("viewState.version") == state["version"], f"the page at version {state['version']}")
        got = page.eval("viewState.confirmedIds()")
        updates = page.eval("viewState.updates")
        shot = page.send("Page.captureScreenshot", format="png")["data"]
        os.makedirs(os.path.join(HERE, "out"), exist_ok=True)
        path = os.path.join(HERE, "out", "view.png")
        import base64
        open(path, "wb").write(base64.b64decode(shot))
        print(f"session {sid}: version {state['version']}, {updates} update events, "
              f"confirmed tracks in the session {want}, drawn {got}; screenshot {path}")
        if not want:
            raise SystemExit("FAIL: the scene gave no confirmed track")
        if got != want:
            raise SystemExit("FAIL: the page does not draw the session's confirmed tracks")
        print("OK")
    finally:
        if browser:
            browser.kill()
        server.kill()


def ok(url):
    try:
        return urllib.request.urlopen(url, timeout=2).status == 200
    except Exception:
        return False


def page_targets():
    try:
        t = json.load(urllib.request.urlopen(f"http://127.0.0.1:{CDP}/json/list", timeout=2))
        return [x for x in t if x.get("type") == "page"]
    except Exception:
        return None


if __name__ == "__main__":
    main()
