#!/usr/bin/env python3
"""brume view under hostile peers that have no token (issue #51; docs/reliability.md, docs/view.md).

  check_view_hostile.py --brume build/brume            the bounds, asserted (ctest view_hostile_peers)
  check_view_hostile.py --brume build/brume --measure  the same probes, measured and printed (no assertion)

Each probe starts its own `brume view` on the demo scene (160x112) and attacks it from this process:

  stall     200 silent connections and 20 slow-loris connections (a request head trickled a byte a second),
            each reopened as soon as the server closes it, as an attacker would; meanwhile a token-bearing
            GET of the page on a fresh connection every 0.5 s: each must be answered within 1 s
  cap       1000 connections trickling a byte a second (more than the server keeps, and than its default
            descriptor limit of 1024 allows with the rest): the token-bearing GETs as above
  headers   four connections each sending one endless header line (up to 160 MiB each) and two sending
            endless short header lines: the server's RSS stays under 100 MB, and it closes all six
  body      a keep-alive GET (with the token, so past every check before the body) announcing a 200 MB
            body and sending it, and a chunked POST of 200 MB: RSS under 100 MB, both closed; a 5 MiB
            chunked frame, and a GET announcing 200 MB: 413; a small frame still works after them
  utf8      invalid UTF-8 in a frame (in a value, in a key, outside a string): 400, and no response carries
            exception text (no EXCEPTION_WHAT header, no "json.exception", "what()", "std::")
  sigterm   SIGTERM with all of the above connected (200 silent, 20 slow, 4 endless header lines, a body
            being sent, the page's keep-alive connection): the server exits 0 within 2 s

RSS is VmRSS from /proc/PID/status, sampled every 20 ms (VmHWM, the kernel's own peak, is reported too).

Bounds and margins (a CI host may be a loaded 2-core machine; measured here with load 9-11 on 2 vCPU):
the issue's 1 s for a token-bearing request, 100 MB of RSS and 2 s for SIGTERM are asserted as they are;
docs/reliability.md gives what they measured, well inside each.
"""
import argparse
import http.client
import json
import os
import resource
import select
import signal
import socket
import sys
import tempfile
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from check_view import demo, split, start_view  # noqa: E402

MB = 1e6


def rss_mb(pid):
    """(VmRSS, VmHWM) in MB from /proc, or (0, 0) when the process is gone."""
    try:
        with open(f"/proc/{pid}/status") as f:
            kv = dict(l.split(":", 1) for l in f if ":" in l)
        return int(kv["VmRSS"].split()[0]) * 1024 / MB, int(kv["VmHWM"].split()[0]) * 1024 / MB
    except (OSError, KeyError):
        return 0.0, 0.0


class RssSampler(threading.Thread):
    def __init__(self, pid):
        super().__init__(daemon=True)
        self.pid, self.peak, self.stop_ = pid, 0.0, threading.Event()

    def run(self):
        while not self.stop_.is_set():
            self.peak = max(self.peak, rss_mb(self.pid)[0])
            time.sleep(0.02)

    def done(self):
        self.stop_.set()
        self.join()
        return self.peak


def connect(host, port):
    s = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_STREAM)
    s.settimeout(5)
    s.connect((host, port))
    s.setblocking(False)
    return s


def closed_by_peer(s):
    """True when the server closed (or reset) the connection: readable with EOF or an error."""
    try:
        r, _, _ = select.select([s], [], [], 0)
        if not r:
            return False
        while True:
            b = s.recv(65536)
            if not b:
                return True
    except BlockingIOError:
        return False
    except OSError:
        return True


class Crowd(threading.Thread):
    """n connections that send nothing (silent) or a request head a byte a second (slow), each reopened
    as soon as the server closes it (an attacker keeps its connections); counts the server's closes."""

    def __init__(self, host, port, silent, slow):
        super().__init__(daemon=True)
        self.host, self.port = host, port
        self.want = [("silent", i) for i in range(silent)] + [("slow", i) for i in range(slow)]
        self.socks = {}
        self.sent = {}
        self.closed = 0
        self.open_failures = 0
        self.stop_ = threading.Event()
        self.head = (f"GET / HTTP/1.1\r\nHost: {host}:{port}\r\nUser-Agent: slow\r\nX-Slow: " + "a" * 100000).encode()

    def open(self, key):
        try:
            self.socks[key] = connect(self.host, self.port)
            self.sent[key] = 0
        except OSError:
            self.socks.pop(key, None)
            self.open_failures += 1

    def open_all(self):
        for k in self.want:
            self.open(k)

    def run(self):
        next_byte = time.monotonic()
        while not self.stop_.is_set():
            for k in self.want:
                s = self.socks.get(k)
                if s is not None and closed_by_peer(s):
                    s.close()
                    self.closed += 1
                    s = None
                if s is None:
                    self.open(k)
            if time.monotonic() >= next_byte:
                next_byte += 1.0
                for k in self.want:
                    s = self.socks.get(k)
                    if k[0] == "slow" and s is not None:
                        try:
                            s.send(self.head[self.sent[k]:self.sent[k] + 1])
                            self.sent[k] += 1
                        except OSError:
                            pass
            self.stop_.wait(0.1)

    def finish(self):
        self.stop_.set()
        self.join()
        for s in self.socks.values():
            s.close()


def token_get(url, timeout):
    """Seconds until the page (GET /TOKEN/) is answered 200 on a fresh connection, or None."""
    host, port, base = split(url)
    t0 = time.monotonic()
    try:
        c = http.client.HTTPConnection(host, port, timeout=timeout)
        c.request("GET", base, headers={"Host": f"{host}:{port}"})
        r = c.getresponse()
        r.read()
        c.close()
        return time.monotonic() - t0 if r.status == 200 else None
    except OSError:
        return None


def probe_requests(url, seconds, every=0.5, timeout=8.0):
    """Token-bearing GETs every `every` s for `seconds` s, each in its own thread; their latencies."""
    out = []
    threads = []

    def one(i):
        out.append((i, token_get(url, timeout)))

    t_end = time.monotonic() + seconds
    i = 0
    while time.monotonic() < t_end:
        th = threading.Thread(target=one, args=(i,), daemon=True)
        th.start()
        threads.append(th)
        i += 1
        time.sleep(every)
    for th in threads:
        th.join()
    return [v for _, v in sorted(out)]


class Flood(threading.Thread):
    """One connection sending `head` then `chunk` repeatedly up to `limit` bytes or until the server closes it."""

    def __init__(self, host, port, head, chunk, limit, seconds=30.0):
        super().__init__(daemon=True)
        self.host, self.port, self.head, self.chunk, self.limit, self.seconds = host, port, head, chunk, limit, seconds
        self.sent, self.closed, self.reply = 0, False, b""
        self.stop_ = threading.Event()

    def run(self):
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        s.settimeout(5)
        try:
            s.connect((self.host, self.port))
            s.sendall(self.head)
            t_end = time.monotonic() + self.seconds
            s.setblocking(False)
            # Sends on as a hostile client would, also after a reply, until the server closes the connection.
            while self.sent < self.limit and time.monotonic() < t_end and not self.stop_.is_set():
                r, w, _ = select.select([s], [s], [], 0.5)
                if r:
                    b = s.recv(65536)
                    if not b:
                        self.closed = True
                        break
                    self.reply += b
                elif w:
                    self.sent += s.send(self.chunk)
        except OSError:
            self.closed = True
        try:
            s.setblocking(True)
            s.settimeout(2)
            while not self.stop_.is_set():
                b = s.recv(65536)
                if not b:
                    self.closed = True
                    break
                self.reply += b
        except OSError:
            pass
        s.close()


def raw(url, data, timeout=10.0):
    """Sends `data` on a fresh connection and reads the reply until the server closes or `timeout`; the
    reply's status (None when no status line came back) and its bytes."""
    host, port, _ = split(url)
    s = socket.create_connection((host, port), timeout=timeout)
    reply = b""
    try:
        s.sendall(data)
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end:
            b = s.recv(65536)
            if not b:
                break
            reply += b
            if b"\r\n\r\n" in reply:
                head, _, body = reply.partition(b"\r\n\r\n")
                cl = [l for l in head.split(b"\r\n") if l.lower().startswith(b"content-length:")]
                if cl and len(body) >= int(cl[0].split(b":")[1]):
                    break
    except OSError:
        pass
    s.close()
    status = int(reply.split(b" ", 2)[1]) if reply.startswith(b"HTTP/1.") else None
    return status, reply


def chunked(body, size=65536):
    out = bytearray()
    for i in range(0, len(body), size):
        part = body[i:i + size]
        out += b"%x\r\n" % len(part) + part + b"\r\n"
    return bytes(out) + b"0\r\n\r\n"


class Probes:
    def __init__(self, brume, tmp, measure):
        self.brume, self.tmp, self.measure = brume, tmp, measure
        self.results = {}
        self.failed = []

    def check(self, cond, what):
        if self.measure:
            print(("ok:  " if cond else "(over) ") + what, flush=True)
            return
        print(("ok: " if cond else "FAIL: ") + what, flush=True)
        if not cond:
            self.failed.append(what)

    def serve(self):
        p, url = start_view(self.brume, ["--image", "clean.png", "--range", "range.exr", "--idle-exit", "5"], self.tmp)
        host, port, base = split(url)
        return p, url, host, port, base

    def stop(self, p):
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
            try:
                p.wait(30)
            except Exception:
                p.kill()
                p.wait()

    def stall(self, silent=200, slow=20, name="stall"):
        p, url, host, port, base = self.serve()
        base_rss = rss_mb(p.pid)[0]
        sampler = RssSampler(p.pid)
        sampler.start()
        crowd = Crowd(host, port, silent, slow)
        crowd.open_all()
        crowd.start()
        time.sleep(1.0)  # all connected and the first bytes trickling
        lat = probe_requests(url, 12.0)
        crowd.finish()
        peak = sampler.done()
        answered = [v for v in lat if v is not None]
        worst = max(answered) if answered else None
        self.results[name] = {"token_gets": len(lat), "answered": len(answered),
                              "worst_s": worst, "median_s": sorted(answered)[len(answered) // 2] if answered else None,
                              "closed_by_server": crowd.closed, "open_failures": crowd.open_failures,
                              "rss_mb": round(peak, 1), "rss_start_mb": round(base_rss, 1)}
        self.check(len(answered) == len(lat) and worst is not None and worst < 1.0,
                   f"{name}: {silent} silent + {slow} slow connections: {len(answered)}/{len(lat)} token-bearing GETs "
                   f"answered, the slowest in {worst if worst is None else round(worst, 3)} s (bound 1 s); "
                   f"the server closed {crowd.closed} of the attacker's connections")
        self.stop(p)

    def cap(self):
        soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
        if soft < 1200:  # the server (started before this) keeps its own limit
            resource.setrlimit(resource.RLIMIT_NOFILE, (min(hard, 4096), hard))
        self.stall(silent=0, slow=1000, name="cap")

    def headers(self):
        p, url, host, port, base = self.serve()
        sampler = RssSampler(p.pid)
        sampler.start()
        long_head = f"GET / HTTP/1.1\r\nHost: {host}:{port}\r\nX-Endless: ".encode()
        floods = [Flood(host, port, long_head, b"a" * 65536, 160 << 20) for _ in range(4)]
        floods += [Flood(host, port, long_head + b"a\r\n", b"X-Again: a\r\n" * 5000, 160 << 20) for _ in range(2)]
        t0 = time.monotonic()
        for f in floods:
            f.start()
        for f in floods:
            f.join()
        peak = sampler.done()
        hwm = rss_mb(p.pid)[1]
        statuses = [f.reply.split(b" ", 2)[1].decode() if f.reply.startswith(b"HTTP/1.") else "-" for f in floods]
        self.results["headers"] = {"rss_mb": round(peak, 1), "hwm_mb": round(hwm, 1),
                                   "sent_mib": [round(f.sent / 2 ** 20, 2) for f in floods],
                                   "closed": [f.closed for f in floods], "status": statuses,
                                   "seconds": round(time.monotonic() - t0, 2)}
        self.check(peak < 100, f"headers: 4 endless header lines and 2 endless header lists: RSS {peak:.1f} MB "
                               f"(VmHWM {hwm:.1f}) < 100 MB; sent {[round(f.sent / 2**20, 2) for f in floods]} MiB")
        self.check(all(f.closed for f in floods), f"headers: the server closed all six (replies {statuses})")
        self.check(token_get(url, 5) is not None, "headers: the page is served after them")
        self.stop(p)

    def body(self):
        p, url, host, port, base = self.serve()
        sampler = RssSampler(p.pid)
        sampler.start()
        h = f"Host: {host}:{port}\r\n"
        get = Flood(host, port, f"GET {base} HTTP/1.1\r\n{h}Content-Length: 200000000\r\n\r\n".encode(),
                    b"a" * 65536, 200_000_000)
        post = Flood(host, port, f"POST {base}frame HTTP/1.1\r\n{h}Transfer-Encoding: chunked\r\n\r\n".encode(),
                     b"10000\r\n" + b" " * 65536 + b"\r\n", 200_000_000)
        get.start()
        post.start()
        get.join()
        post.join()
        peak = sampler.done()
        hwm = rss_mb(p.pid)[1]

        def st(reply):
            return int(reply.split(b" ", 2)[1]) if reply.startswith(b"HTTP/1.") else None
        frame = json.dumps({"values": {"visibility": "300"}}).encode()
        five = b"{" + b" " * (5 << 20) + frame[1:]
        s5, _ = raw(url, f"POST {base}frame HTTP/1.1\r\n{h}Transfer-Encoding: chunked\r\n\r\n".encode() + chunked(five))
        s200, _ = raw(url, f"GET {base} HTTP/1.1\r\n{h}Content-Length: 200000000\r\n\r\n".encode())
        small, _ = raw(url, f"POST {base}frame HTTP/1.1\r\n{h}Transfer-Encoding: chunked\r\nConnection: close\r\n\r\n"
                       .encode() + chunked(frame, 7))
        self.results["body"] = {"rss_mb": round(peak, 1), "hwm_mb": round(hwm, 1),
                                "get_200mb": {"sent_mib": round(get.sent / 2**20, 2), "closed": get.closed,
                                              "status": st(get.reply)},
                                "chunked_200mb": {"sent_mib": round(post.sent / 2**20, 2), "closed": post.closed,
                                                  "status": st(post.reply)},
                                "chunked_5mib_status": s5, "get_announcing_200mb_status": s200,
                                "small_chunked_frame_status": small}
        self.check(peak < 100, f"body: a keep-alive GET sending 200 MB and a chunked POST of 200 MB: RSS {peak:.1f} MB "
                               f"(VmHWM {hwm:.1f}) < 100 MB (sent {get.sent / 2**20:.2f} and {post.sent / 2**20:.2f} MiB)")
        self.check(get.closed and post.closed and st(get.reply) == 413 and st(post.reply) == 413,
                   f"body: both answered 413 and closed ({st(get.reply)}, {st(post.reply)})")
        self.check(s5 == 413, f"body: a 5 MiB chunked frame: 413 (got {s5})")
        self.check(s200 == 413, f"body: a GET announcing 200 MB: 413 (got {s200})")
        self.check(small == 200, f"body: a small chunked frame: 200 (got {small})")
        self.stop(p)

    def utf8(self):
        p, url, host, port, base = self.serve()
        h = f"Host: {host}:{port}\r\n"
        cases = {"in a value": b'{"values": {"visibility": "3\xff00"}}',
                 "in a key": b'{"values": {"visib\xc3ility": "300"}}',
                 "outside a string": b'{"values": {"visibility": "300"}\xfe}',
                 "an overlong form": b'{"values": {"visibility": "\xc0\xaf"}}',
                 "a lone surrogate escape": b'{"values": {"visibility": "\\udc80"}}'}
        out = {}
        leaks = []
        for what, body in cases.items():
            st, reply = raw(url, f"POST {base}frame HTTP/1.1\r\n{h}Content-Length: {len(body)}\r\n"
                                 f"Connection: close\r\n\r\n".encode() + body)
            out[what] = st
            low = reply.lower()
            if b"exception_what" in low or b"json.exception" in low or b"what()" in low or b"std::" in low:
                leaks.append(what)
            self.check(st == 400, f"utf8: invalid UTF-8 {what}: 400 (got {st}: {reply[-120:]!r})")
        self.results["utf8"] = {"status": out, "leaks": leaks}
        self.check(not leaks, f"utf8: no response carries exception text ({leaks})")
        self.stop(p)

    def sigterm(self, everyone=True, name="sigterm"):
        p, url, host, port, base = self.serve()
        # The page's keep-alive connection, idle after a request (the browser holds one).
        page = http.client.HTTPConnection(host, port, timeout=10)
        page.request("GET", base + "meta.json", headers={"Host": f"{host}:{port}"})
        page.getresponse().read()
        crowd = Crowd(host, port, 200 if everyone else 0, 20 if everyone else 5)
        crowd.open_all()
        crowd.start()
        long_head = f"GET / HTTP/1.1\r\nHost: {host}:{port}\r\nX-Endless: ".encode()
        floods = [Flood(host, port, long_head, b"a" * 65536, 160 << 20) for _ in range(4 if everyone else 0)]
        if everyone:
            floods.append(Flood(host, port, f"GET {base} HTTP/1.1\r\nHost: {host}:{port}\r\nContent-Length: 200000000\r\n\r\n"
                            .encode(), b"a" * 65536, 200_000_000))
        for f in floods:
            f.start()
        time.sleep(1.5 if everyone else 4.0)
        t0 = time.monotonic()
        p.send_signal(signal.SIGTERM)
        try:
            rc = p.wait(60)
        except subprocess_timeout():
            rc = None
        took = time.monotonic() - t0
        for f in floods:
            f.stop_.set()
        crowd.finish()
        page.close()
        if rc is None:
            p.kill()
            p.wait()
        self.results[name] = {"seconds": round(took, 3), "exit": rc}
        self.check(rc == 0 and took < 2.0, f"{name}: with {'all of them' if everyone else 'five slow-loris'} connected, "
                                           f"stopped in {took:.2f} s (bound 2 s), exit {rc}")

    def sigterm_slow(self):
        self.sigterm(everyone=False, name="sigterm_slow")


def subprocess_timeout():
    import subprocess
    return subprocess.TimeoutExpired


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--brume", required=True)
    ap.add_argument("--measure", action="store_true", help="print the measurements; assert nothing")
    ap.add_argument("probes", nargs="*", default=["stall", "cap", "headers", "body", "utf8", "sigterm", "sigterm_slow"])
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        demo(os.path.abspath(a.brume), tmp)
        pr = Probes(os.path.abspath(a.brume), tmp, a.measure)
        for name in a.probes:
            try:
                getattr(pr, name)()
            except Exception as e:  # a probe that cannot finish against this server is a failure, not a crash
                pr.results.setdefault(name, {})["error"] = repr(e)
                pr.check(False, f"{name}: {e!r}")
        print(json.dumps(pr.results))
        if pr.failed:
            print(f"FAILED: {len(pr.failed)} check(s)")
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
