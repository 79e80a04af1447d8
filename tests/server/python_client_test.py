#!/usr/bin/env python3
"""The documented Python client (clients/python) against a real `fluxcal
serve`: example.py end to end (ingest, fit, query, export, write) with its
--json output asserted, a rerun that replays the run, the same with a bearer
token on a server with --auth, and server reflection v1 and v1alpha
(list_services, file_containing_symbol; UNAUTHENTICATED without a token).
Issue 25 and 24: loopback judged by what an address resolves to and no token
in clear off loopback (the rule of io/net.h), a missing server reported as a
message (ServerUnreachableError; example.py exits 1 without a traceback),
`reliable` True when a point leaves it out and a warning for a run of
unreliable points.
Usage: python_client_test.py FLUXCAL_BINARY CLIENT_DIR PROTO_DIR"""
import contextlib
import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import warnings

import grpc
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

BINARY, CLIENT_DIR, PROTO_DIR = sys.argv[1], sys.argv[2], sys.argv[3]
WORK = tempfile.mkdtemp(prefix="fluxcal_pyclient_")
failures = []


def check(cond, what):
    if not cond:
        failures.append(what)
        print(f"FAIL: {what}", file=sys.stderr)


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def serve(name, extra=()):
    port = free_port()
    db = os.path.join(WORK, name + ".db")
    proc = subprocess.Popen([BINARY, "serve", "--db", db, "--listen", f"127.0.0.1:{port}", "--quiet", *extra],
                            stderr=subprocess.DEVNULL)
    return proc, f"127.0.0.1:{port}"


def example(addr, serial, out, *extra):
    # The generated stubs are shared by every run (FLUXCAL_PY_GEN): the
    # first run generates them.
    env = dict(os.environ, FLUXCAL_PY_GEN=os.path.join(WORK, "gen"))
    r = subprocess.run([sys.executable, os.path.join(CLIENT_DIR, "example.py"), "--server", addr, "--serial", serial,
                        "--out", out, "--json", *extra], capture_output=True, text=True, env=env, timeout=240)
    if r.returncode != 0:
        print(r.stderr, file=sys.stderr)
    return r.returncode, r.stdout, r.stderr


def check_example_output(code, stdout, serial, out, version, replayed):
    check(code == 0, f"{serial}: example exit code {code}")
    doc = json.loads(stdout)   # exactly one JSON document
    check(doc["serial"] == serial, f"{serial}: serial {doc['serial']}")
    check(doc["accepted"] == 36, f"{serial}: accepted {doc['accepted']}")
    # The client raises unless the reply's digest is its own over what it sent.
    check(len(doc["points_sha256"]) == 64, f"{serial}: points_sha256 {doc['points_sha256']}")
    check(doc["replayed"] is replayed, f"{serial}: replayed {doc['replayed']}")
    check(doc["version"] == version, f"{serial}: version {doc['version']}")
    check(doc["pass"] is True and doc["verdict"] == "pass", f"{serial}: verdict {doc['verdict']}")
    # The synthetic motor's magnet flux is 11.4 mWb (clients/python/example.py).
    check(abs(doc["psi_pm_wb"] / 0.0114 - 1) < 0.02, f"{serial}: psi_pm_wb {doc['psi_pm_wb']}")
    q = doc["query"]
    check(len(q) == 2, f"{serial}: {len(q)} query values")
    # At id = 0 the d flux is the magnet flux plus the cross-saturation
    # term, which the synthetic points set to zero.
    check(abs(q[1]["psi_d_wb"] / doc["psi_pm_wb"] - 1) < 0.01, f"{serial}: psi_d at (0, 100) {q[1]['psi_d_wb']}")
    check(all(v["psi_d_wb_std"] > 0 and v["torque_nm"] > 0 for v in q), f"{serial}: query {q}")
    with open(out, "rb") as f:
        data = f.read()
    check(len(data) == doc["table"]["bytes"], f"{serial}: {out} holds {len(data)} bytes")
    table = json.loads(data)
    check(table["kind"] == "mtpa" and table["serial"] == serial, f"{serial}: table {table['kind']} {table['serial']}")
    crc = table.get("payload_crc32", table.get("crc32"))   # fluxcal.table.v2 / v1
    check(crc == doc["table"]["crc32"], f"{serial}: payload crc32 {crc} vs {doc['table']['crc32']}")


def reflection_classes():
    """Message classes of both reflection protos, built from protoc's
    descriptor set: no generated module (its package would be `grpc`,
    shadowed by grpcio's)."""
    ds = os.path.join(WORK, "reflection.pb")
    # v1alpha is v1 but for its package: written from it, as
    # proto/CMakeLists.txt does for the server.
    alpha_root = os.path.join(WORK, "reflection_v1alpha")
    os.makedirs(os.path.join(alpha_root, "grpc", "reflection", "v1alpha"), exist_ok=True)
    with open(os.path.join(PROTO_DIR, "grpc", "reflection", "v1", "reflection.proto")) as f:
        v1 = f.read()
    with open(os.path.join(alpha_root, "grpc", "reflection", "v1alpha", "reflection.proto"), "w") as f:
        f.write(v1.replace("package grpc.reflection.v1;", "package grpc.reflection.v1alpha;"))
    subprocess.run(["protoc", f"-I{PROTO_DIR}", f"-I{alpha_root}", f"--descriptor_set_out={ds}",
                    "grpc/reflection/v1/reflection.proto", "grpc/reflection/v1alpha/reflection.proto"], check=True)
    fds = descriptor_pb2.FileDescriptorSet()
    with open(ds, "rb") as f:
        fds.ParseFromString(f.read())
    pool = descriptor_pool.DescriptorPool()
    for fd in fds.file:
        pool.Add(fd)
    factory = message_factory.MessageFactory(pool)
    out = {}
    for v in ("v1", "v1alpha"):
        out[v] = tuple(factory.GetPrototype(pool.FindMessageTypeByName(f"grpc.reflection.{v}.{m}"))
                       for m in ("ServerReflectionRequest", "ServerReflectionResponse"))
    return out


def check_reflection(addr, metadata, classes):
    channel = grpc.insecure_channel(addr)
    for v, (Req, Resp) in classes.items():
        call = channel.stream_stream(f"/grpc.reflection.{v}.ServerReflection/ServerReflectionInfo",
                                     request_serializer=Req.SerializeToString, response_deserializer=Resp.FromString)
        reqs = [Req(list_services=""), Req(file_containing_symbol="fluxcal.v1.CalibrationService"),
                Req(file_by_filename="no/such.proto")]
        try:
            replies = list(call(iter(reqs), timeout=20, metadata=metadata))
        except grpc.RpcError as e:
            check(False, f"reflection {v}: {e.code().name}: {e.details()}")
            continue
        check(len(replies) == 3, f"reflection {v}: {len(replies)} replies")
        names = {s.name for s in replies[0].list_services_response.service}
        for want in ("fluxcal.v1.CalibrationService", "grpc.reflection.v1.ServerReflection",
                     "grpc.reflection.v1alpha.ServerReflection"):
            check(want in names, f"reflection {v}: list_services lacks {want}: {sorted(names)}")
        fd = descriptor_pb2.FileDescriptorProto()
        fd.ParseFromString(replies[1].file_descriptor_response.file_descriptor_proto[0])
        check(fd.name == "fluxcal/v1/calibration.proto" and fd.service[0].name == "CalibrationService",
              f"reflection {v}: file_containing_symbol gave {fd.name}")
        check(replies[2].error_response.error_code == grpc.StatusCode.NOT_FOUND.value[0],
              f"reflection {v}: unknown file gave {replies[2]}")
    channel.close()


def check_digest_form():
    """The client's hf_points_sha256 gives the value pipeline::HfPointsSha256
    gives for the same points (the golden value of
    tests/pipeline/pipeline_test.cc, IngestStream.DigestsHaveTheDocumentedForm)."""
    sys.path.insert(0, CLIENT_DIR)
    import fluxcal_client
    pb, _ = fluxcal_client.load_stubs(os.path.join(WORK, "gen"), PROTO_DIR)
    a = pb.HfPoint(point_id="p0", id_a=-20, iq_a=40, speed_rpm=1500, ld_h=1.8e-4, lq_h=3.6e-4, ldq_h=-1.25e-6,
                   ld_h_std=1e-7, lq_h_std=2e-7, ldq_h_std=3e-7, temperature_c=25, reliable=True)
    b = pb.HfPoint(point_id="p1", id_a=-0.0, iq_a=100, ld_h=2e-4, lq_h=4e-4, temperature_c=31.5, reliable=False)
    got = fluxcal_client.hf_points_sha256([a, b])
    want = "22e7c253c7ba13bdab6539be3f8fba08288e5e31a45100ad0037a57d316856df"
    check(got == want, f"hf_points_sha256: {got}, the C++ form gives {want}")
    # A point with the injection's flux radius (schema v9): the golden value
    # of the same C++ test, point b with hf_flux_radius_wb = 1.6e-3.
    b.hf_flux_radius_wb = 1.6e-3
    got = fluxcal_client.hf_points_sha256([a, b])
    want = "2f7393121b26de7d2f55bd26262e6038ba2cb0a45d4ad3381cfa548a15a8aaf8"
    check(got == want, f"hf_points_sha256 with hf_flux_radius_wb: {got}, the C++ form gives {want}")


@contextlib.contextmanager
def fake_resolver(table):
    """socket.getaddrinfo answering the names in `table` (name -> list of
    numeric addresses) and every other name as the system does."""
    real = socket.getaddrinfo

    def fake(host, port, *args, **kwargs):
        if host in table:
            out = []
            for a in table[host]:
                fam = socket.AF_INET6 if ":" in a else socket.AF_INET
                out.append((fam, socket.SOCK_STREAM, 6, "", (a, 0) if fam == socket.AF_INET else (a, 0, 0, 0)))
            return out
        return real(host, port, *args, **kwargs)

    socket.getaddrinfo = fake
    try:
        yield
    finally:
        socket.getaddrinfo = real


def check_loopback_rule():
    """Loopback is what an address resolves to, every address of it (the
    rule of io/net.h), not how it is spelt: the old client took
    `127.plant.example` for loopback and sent a token in clear to it."""
    sys.path.insert(0, CLIENT_DIR)
    import fluxcal_client as fc
    names = {"127.plant.example": ["10.20.0.5"], "mixed.example": ["127.0.0.1", "10.0.0.1"],
             "lo.example": ["127.0.0.5", "::1"], "mapped.example": ["::ffff:127.0.0.1"]}
    want = {"127.0.0.1:50051": True, "127.1.2.3:1": True, "[::1]:50051": True, "unix:/tmp/fluxcal.sock": True,
            "dns:///127.0.0.1:1": True, "dns://8.8.8.8/127.0.0.1:1": True, "lo.example:1": True,
            "mapped.example:1": True, "127.plant.example:50051": False, "mixed.example:1": False,
            "ipv4:127.0.0.1:1,10.0.0.1:1": False, "ipv4:127.0.0.1:1,127.0.0.2:1": True, "10.1.2.3:1": False,
            ":50051": False, "0.0.0.0:1": False, "[::]:1": False, "127.no-such-host.invalid:1": False}
    with fake_resolver(names):
        for address, loopback in want.items():
            got, why = fc.check_loopback(address)
            check(got is loopback, f"check_loopback({address!r}) = {got} ({why}), expected {loopback}")
        _, why = fc.check_loopback("127.plant.example:50051")
        check("10.20.0.5" in why, f"check_loopback names what the address resolves to: {why}")
        # A token in clear off loopback is refused before any connection,
        # also with insecure=True; to loopback it is sent.
        for address in ("127.plant.example:50051", "10.255.255.1:50051", "mixed.example"):
            try:
                fc.Client(address, token="secret", insecure=True, gen_dir=os.path.join(WORK, "gen"),
                          proto_dir=PROTO_DIR)
                check(False, f"{address}: a token in plaintext off loopback was not refused")
            except RuntimeError as e:
                check("tokens need TLS off loopback" in str(e), f"{address}: {e}")
        fc.Client("lo.example:1", token="secret", gen_dir=os.path.join(WORK, "gen"), proto_dir=PROTO_DIR).close()
    for server, target in (("h", "h:50051"), ("h:1", "h:1"), ("[::1]", "[::1]:50051"), ("::1", "[::1]:50051"),
                           ("[::1]:7", "[::1]:7"), ("unix:/s", "unix:/s"), ("dns:///h:1", "dns:///h:1")):
        check(fc.server_target(server) == target, f"server_target({server!r}) = {fc.server_target(server)!r}")


def check_missing_server():
    """A server that is not there: a message naming the address and what to
    check, not grpc's FutureTimeoutError traceback."""
    sys.path.insert(0, CLIENT_DIR)
    import fluxcal_client as fc
    addr = f"127.0.0.1:{free_port()}"   # nothing listens there
    c = fc.Client(addr, gen_dir=os.path.join(WORK, "gen"), proto_dir=PROTO_DIR)
    try:
        c.wait_ready(timeout_s=1.0)
        check(False, f"{addr}: wait_ready returned without a server")
    except fc.ServerUnreachableError as e:
        check(isinstance(e, fc.FluxcalError) and addr in str(e) and "fluxcal serve" in str(e),
              f"wait_ready without a server: {e}")
    finally:
        c.close()
    code, stdout, stderr = example(addr, "IPM-PY-NONE", os.path.join(WORK, "none.json"), "--connect-timeout-s", "1")
    check(code == 1, f"example without a server: exit {code}, expected 1")
    check("Traceback" not in stderr and "FutureTimeoutError" not in stderr, f"example without a server: {stderr}")
    check(f"cannot reach {addr}" in stderr and "fluxcal serve" in stderr, f"example without a server: {stderr}")
    check(stdout == "", f"example without a server printed on stdout: {stdout!r}")


def check_reliable_default(addr):
    """A point that leaves `reliable` out is reliable (before: the proto's
    false, 36 of 36 points unreliable and a failed verdict, silently); a run
    of points all marked unreliable is sent with a warning."""
    sys.path.insert(0, CLIENT_DIR)
    import fluxcal_client as fc
    import example as ex
    with fc.Client(addr, gen_dir=os.path.join(WORK, "gen"), proto_dir=PROTO_DIR) as c:
        c.wait_ready(10.0)
        points = ex.synthetic_points()
        for p in points:
            del p["reliable"]
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            c.ingest_hf_results("IPM-PY-REL-1", points, motor=ex.MOTOR)
        check(not w, f"a run of reliable points warned: {[str(x.message) for x in w]}")
        fit = c.fit("IPM-PY-REL-1")
        check(fit.calibration.verdict == "pass", f"points without `reliable`: verdict {fit.calibration.verdict}")
        for p in points:
            p["reliable"] = False
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            c.ingest_hf_results("IPM-PY-REL-2", points, motor=ex.MOTOR)
        check(len(w) == 1 and issubclass(w[0].category, fc.UnreliablePointsWarning)
              and "all 36 points" in str(w[0].message), f"all unreliable: warnings {[str(x.message) for x in w]}")
        fit = c.fit("IPM-PY-REL-2")
        check(fit.calibration.verdict.startswith("fail: 36 of 36 points flagged unreliable"),
              f"all unreliable: verdict {fit.calibration.verdict}")


def main():
    check_digest_form()
    check_loopback_rule()
    check_missing_server()
    classes = reflection_classes()
    # Open server on loopback (no --auth): every caller is admin.
    proc, addr = serve("open")
    try:
        out = os.path.join(WORK, "mtpa.json")
        code, stdout, _ = example(addr, "IPM-PY-EX-1", out)
        check_example_output(code, stdout, "IPM-PY-EX-1", out, version=1, replayed=False)
        # A rerun replays the stored run (same content, same key) and fits
        # it again: calibration version 2.
        code, stdout, _ = example(addr, "IPM-PY-EX-1", out)
        check_example_output(code, stdout, "IPM-PY-EX-1", out, version=2, replayed=True)
        check_reflection(addr, (), classes)
        check_reliable_default(addr)
        # A bad serial: exit 1, the message names the RPC and the field.
        code, _, stderr = example(addr, "bad serial!", out)
        check(code == 1 and "IngestHfResults" in stderr and "serial" in stderr, f"bad serial: {code} {stderr}")
    finally:
        proc.terminate()
        proc.wait(timeout=10)
    # With identities: the token goes in the metadata of every call.
    keys = os.path.join(WORK, "keys.json")
    add = subprocess.run([BINARY, "admin", "add-key", "--keys", keys, "--name", "py-admin", "--role", "admin",
                          "--json"], capture_output=True, text=True, check=True)
    token_file = os.path.join(WORK, "token")
    with open(token_file, "w") as f:
        f.write(json.loads(add.stdout)["token"] + "\n")
    proc, addr = serve("auth", ["--auth", keys])
    try:
        out = os.path.join(WORK, "mtpa_auth.json")
        code, stdout, _ = example(addr, "IPM-PY-EX-2", out, "--token-file", token_file)
        check_example_output(code, stdout, "IPM-PY-EX-2", out, version=1, replayed=False)
        code, _, stderr = example(addr, "IPM-PY-EX-3", out)
        check(code == 1 and "UNAUTHENTICATED" in stderr, f"no token: exit {code}: {stderr}")
        with open(token_file) as f:
            token = f.read().strip()
        check_reflection(addr, (("authorization", f"Bearer {token}"),), classes)
        # Reflection without a credential: UNAUTHENTICATED, as every RPC but health.
        Req, Resp = classes["v1"]
        channel = grpc.insecure_channel(addr)
        call = channel.stream_stream("/grpc.reflection.v1.ServerReflection/ServerReflectionInfo",
                                     request_serializer=Req.SerializeToString, response_deserializer=Resp.FromString)
        try:
            list(call(iter([Req(list_services="")]), timeout=20))
            check(False, "anonymous reflection answered")
        except grpc.RpcError as e:
            check(e.code() == grpc.StatusCode.UNAUTHENTICATED, f"anonymous reflection: {e.code().name}")
        channel.close()
    finally:
        proc.terminate()
        proc.wait(timeout=10)
    print(f"python client: {'0 failed' if not failures else f'{len(failures)} failed'}")
    if not failures:
        shutil.rmtree(WORK, ignore_errors=True)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
