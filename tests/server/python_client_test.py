#!/usr/bin/env python3
"""The documented Python client (clients/python) against a real `fluxcal
serve`: example.py end to end (ingest, fit, query, export, write) with its
--json output asserted, a rerun that replays the run, the same with a bearer
token on a server with --auth, and server reflection v1 and v1alpha
(list_services, file_containing_symbol; UNAUTHENTICATED without a token).
Usage: python_client_test.py FLUXCAL_BINARY CLIENT_DIR PROTO_DIR"""
import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile

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
    subprocess.run(["protoc", f"-I{PROTO_DIR}", f"--descriptor_set_out={ds}",
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


def main():
    check_digest_form()
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
