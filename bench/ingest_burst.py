#!/usr/bin/python3
"""Server memory under a burst of large uploads from ONE identity.

Starts `fluxcal serve` (open on loopback: every caller is the one identity
"local"), records the server's resident size (VmRSS) idle, then runs
STREAMS parallel IngestRecording streams of MB mebibytes each (1 MiB chunks
of filler: the server assembles them, then refuses the set), samples the
peak VmRSS, and the idle VmRSS again after the burst. Prints one JSON
document. Uses Debian's python3-grpcio only: the RecordingChunk messages
are encoded by hand (fields 1 serial, 3 path, 4 data; proto/fluxcal/v1).

  /usr/bin/python3 bench/ingest_burst.py --streams 8 --mb 248 [--rounds 3] build/cli/fluxcal [SERVE FLAGS...]

docs/security.md ("Limits per identity") quotes its numbers.
"""
import argparse
import collections
import json
import os
import re
import subprocess
import sys
import tempfile
import threading
import time

import grpc


def varint(n):
    out = bytearray()
    while True:
        b = n & 0x7F
        n >>= 7
        out.append(b | (0x80 if n else 0))
        if not n:
            return bytes(out)


def field(number, payload):
    return varint(number << 3 | 2) + varint(len(payload)) + payload


def chunk(serial, path, data):
    return (field(1, serial.encode()) if serial else b"") + field(3, path.encode()) + field(4, data)


def rss_bytes(pid):
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    return 0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--streams", type=int, default=8)
    ap.add_argument("--mb", type=int, default=248)
    ap.add_argument("--rounds", type=int, default=1, help="bursts one after the other on the same server")
    ap.add_argument("fluxcal")
    ap.add_argument("serve_flags", nargs=argparse.REMAINDER, help="flags for fluxcal serve")
    a = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="fluxcal-burst-")
    err = open(os.path.join(tmp, "serve.err"), "w+")
    srv = subprocess.Popen([a.fluxcal, "serve", "--db", os.path.join(tmp, "b.db"), "--listen", "127.0.0.1:0",
                            "--quiet"] + a.serve_flags, stderr=err)
    try:
        port = None
        for _ in range(200):
            err.seek(0)
            m = re.search(r"\(port (\d+)", err.read())
            if m:
                port = int(m.group(1))
                break
            time.sleep(0.05)
        if port is None:
            sys.exit("fluxcal serve did not start")
        channel = grpc.insecure_channel(f"127.0.0.1:{port}", options=[("grpc.max_send_message_length", 8 << 20)])
        ingest = channel.stream_unary("/fluxcal.v1.CalibrationService/IngestRecording",
                                      request_serializer=None, response_deserializer=None)
        time.sleep(0.5)
        idle_before = rss_bytes(srv.pid)
        block = os.urandom(1 << 20)
        codes = collections.Counter()   # of the round running
        messages = {}                    # the first message of each code

        def upload(k):
            def gen():
                for i in range(a.mb):
                    yield chunk(f"IPM-BURST-{k}" if i == 0 else "", "points/p000.csv", block)
            try:
                ingest(gen(), timeout=600)
                codes["OK"] += 1
            except grpc.RpcError as e:
                codes[e.code().name] += 1
                messages.setdefault(e.code().name, e.details()[:300])

        rounds = []
        for _ in range(a.rounds):
            codes = collections.Counter()
            peak = rss_bytes(srv.pid)
            t0 = time.monotonic()
            threads = [threading.Thread(target=upload, args=(k,)) for k in range(a.streams)]
            for t in threads:
                t.start()
            while any(t.is_alive() for t in threads):
                peak = max(peak, rss_bytes(srv.pid))
                time.sleep(0.02)
            seconds = time.monotonic() - t0
            time.sleep(2.0)
            rounds.append({"statuses": dict(codes), "seconds": round(seconds, 2),
                           "rss_peak_mib": round(peak / (1 << 20)),
                           "rss_idle_after_mib": round(rss_bytes(srv.pid) / (1 << 20))})
        print(json.dumps({"streams": a.streams, "stream_mib": a.mb, "serve_flags": a.serve_flags, "messages": messages,
                          "rss_idle_before_mib": round(idle_before / (1 << 20)), "rounds": rounds}, indent=1))
    finally:
        srv.terminate()
        srv.wait(timeout=30)
        err.close()
        subprocess.run(["rm", "-rf", tmp])


if __name__ == "__main__":
    main()
