"""A small Python client for the fluxcal calibration service (fluxcal.v1).

Stubs are generated from proto/fluxcal/v1/calibration.proto when first
needed (`generate_stubs`), never committed: the proto is the contract, and
generated code would drift from it. Generation uses Debian's protoc
(protobuf-compiler, 3.21) with grpc_python_plugin (protobuf-compiler-grpc):
the protoc inside Debian 12's python3-grpc-tools (1.14) predates proto3
`optional`, which HfPoint.ldq_h uses, and refuses the file.

Connection rules are the C++ client's (cli/support_remote.h, io/net.h):
TLS when a CA or a client certificate is given, or when the address is not
loopback (unless insecure=True); loopback is what the address resolves to,
every address of it, never how it is spelt. A bearer token goes in the
`authorization` metadata of every call, and never in plaintext off
loopback: Client refuses before connecting. HOST alone means port 50051.
Units are in field names (`id_a`, `ld_h`, `psi_d_wb`), as in the proto.

A point's `reliable` defaults to True when a point leaves it out (the
proto's bool defaults to false, which the service counts as unreliable: a
run whose points are mostly unreliable fails its verdict); a run whose
points are all unreliable is sent, with an UnreliablePointsWarning.
A server that cannot be reached raises ServerUnreachableError (a
FluxcalError) saying what to check.

    from fluxcal_client import Client
    c = Client("127.0.0.1:50051")
    c.ingest_hf_results("IPM-1", points, motor={"pole_pairs": 4, "psi_pm_wb": 0.0114})
    cal = c.fit("IPM-1")
    print(c.query_flux("IPM-1", [(-20.0, 40.0)])[0].psi_d_wb)
"""
import hashlib
import importlib
import ipaddress
import os
import socket
import struct
import subprocess
import sys
import tempfile
import warnings
import zlib

import grpc

HERE = os.path.dirname(os.path.abspath(__file__))
# clients/python -> the repository's proto/ directory.
DEFAULT_PROTO_DIR = os.path.normpath(os.path.join(HERE, "..", "..", "proto"))
GRPC_PYTHON_PLUGIN = "/usr/bin/grpc_python_plugin"
DEFAULT_PORT = 50051   # `fluxcal serve`'s default (cli/args.h, kDefaultPort)


def hf_points_sha256(points):
    """SHA-256 (hex) of HfPoint messages in the canonical form of
    docs/service.md ("Stream rules"; pipeline::HfPointsSha256 in C++):
    b"fluxcal.hf-points.v1\n", then per point its point_id (4-byte
    big-endian length and UTF-8 bytes), id_a, iq_a, speed_rpm, ld_h, lq_h as
    big-endian binary64, a byte 1 and ldq_h when present (else a byte 0),
    ld_h_std, lq_h_std, ldq_h_std, temperature_c, a byte `reliable`, and,
    only when present, the byte b"r" and hf_flux_radius_wb. A zero is hashed
    as +0.0 (x + 0.0 turns -0.0 into +0.0)."""
    h = hashlib.sha256(b"fluxcal.hf-points.v1\n")

    def f64(*values):
        return struct.pack(f">{len(values)}d", *(v + 0.0 for v in values))

    for p in points:
        pid = p.point_id.encode("utf-8")
        h.update(struct.pack(">I", len(pid)) + pid)
        h.update(f64(p.id_a, p.iq_a, p.speed_rpm, p.ld_h, p.lq_h))
        h.update(b"\x01" + f64(p.ldq_h) if p.HasField("ldq_h") else b"\x00")
        h.update(f64(p.ld_h_std, p.lq_h_std, p.ldq_h_std, p.temperature_c))
        h.update(b"\x01" if p.reliable else b"\x00")
        if p.HasField("hf_flux_radius_wb"):
            h.update(b"r" + f64(p.hf_flux_radius_wb))
    return h.hexdigest()


class StoredNotSentError(Exception):
    """The service acknowledged an ingest, but what it says it stored (count
    or SHA-256) is not what this client sent: nothing may be built on it."""


class FluxcalError(Exception):
    """An RPC failed: `code` is the grpc.StatusCode, the message names the
    RPC, the serial and the server's field-level reason (and, for a server
    that cannot be reached, what to check)."""

    def __init__(self, rpc, serial, code, details, hint=""):
        self.rpc, self.serial, self.code, self.details, self.hint = rpc, serial, code, details, hint
        super().__init__(f"{rpc}{' ' + serial if serial else ''}: {code.name}: {details}" + (f" ({hint})" if hint else ""))


class ServerUnreachableError(FluxcalError):
    """No `fluxcal serve` answered at the address (nothing listening, a
    firewall, TLS where the server speaks plaintext or the reverse, a name
    that does not resolve): raised by wait_ready() instead of grpc's
    FutureTimeoutError, and for UNAVAILABLE on a call."""


class UnreliablePointsWarning(UserWarning):
    """ingest_hf_results sent a run in which every point is marked
    unreliable: the service stores it, and its fit fails the verdict."""


def _unreachable_hint(address):
    return (f"cannot reach {address}: is `fluxcal serve` running there? TLS: give its CA (ca=, example.py --ca; "
            f"cert and key too if it requires client certificates), or insecure (insecure=True, --insecure) for a "
            f"plaintext test server off loopback")


def generate_stubs(out_dir, proto_dir=DEFAULT_PROTO_DIR):
    """Writes fluxcal/v1/calibration_pb2{,_grpc}.py under out_dir.

    Raises RuntimeError naming the missing tool or protoc's complaint."""
    proto = os.path.join(proto_dir, "fluxcal", "v1", "calibration.proto")
    if not os.path.isfile(proto):
        raise RuntimeError(f"{proto}: not found (pass proto_dir, the repository's proto/ directory)")
    if not os.path.exists(GRPC_PYTHON_PLUGIN):
        raise RuntimeError(f"{GRPC_PYTHON_PLUGIN}: not found (apt install protobuf-compiler-grpc)")
    os.makedirs(out_dir, exist_ok=True)
    try:
        r = subprocess.run(["protoc", f"-I{proto_dir}", f"--python_out={out_dir}", f"--grpc_python_out={out_dir}",
                            f"--plugin=protoc-gen-grpc_python={GRPC_PYTHON_PLUGIN}", proto],
                           capture_output=True, text=True)
    except FileNotFoundError:
        raise RuntimeError("protoc: not found (apt install protobuf-compiler)") from None
    if r.returncode != 0:
        raise RuntimeError(f"protoc {proto}: {r.stderr.strip()}")


def load_stubs(gen_dir=None, proto_dir=DEFAULT_PROTO_DIR):
    """Imports (pb2, pb2_grpc), generating them first into gen_dir (default:
    $FLUXCAL_PY_GEN, else a fresh temporary directory) when absent."""
    gen_dir = gen_dir or os.environ.get("FLUXCAL_PY_GEN") or tempfile.mkdtemp(prefix="fluxcal_py_gen_")
    if not os.path.isfile(os.path.join(gen_dir, "fluxcal", "v1", "calibration_pb2_grpc.py")):
        generate_stubs(gen_dir, proto_dir)
    if gen_dir not in sys.path:
        sys.path.insert(0, gen_dir)
    pb = importlib.import_module("fluxcal.v1.calibration_pb2")
    rpc = importlib.import_module("fluxcal.v1.calibration_pb2_grpc")
    return pb, rpc


def server_target(server):
    """The gRPC target for a server address, as the C++ client's --server
    (cli/args.h, ServerTarget): HOST means HOST:50051, [V6] and a bare IPv6
    address get the port too; HOST:PORT, [V6]:PORT and unix:, dns:, ipv4:,
    ipv6: targets are taken as they are."""
    for scheme in ("unix:", "unix-abstract:", "dns:", "ipv4:", "ipv6:", "vsock:"):
        if server.startswith(scheme):
            return server
    if not server:
        return server
    if server.startswith("["):
        return server + f":{DEFAULT_PORT}" if server.endswith("]") else server
    colons = server.count(":")
    if colons == 0:
        return f"{server}:{DEFAULT_PORT}"
    if colons > 1:
        return f"[{server}]:{DEFAULT_PORT}"   # a bare IPv6 address
    return server


def _host_of(item):
    """The host of one HOST:PORT, [V6]:PORT, HOST or bare V6 item."""
    if item.startswith("["):
        close = item.find("]")
        return item[1:close] if close >= 0 else item[1:]
    if item.count(":") == 1:
        return item.split(":", 1)[0]
    return item   # no port, or a bare IPv6 address


def _is_loopback_ip(text):
    try:
        ip = ipaddress.ip_address(text.split("%", 1)[0])   # fe80::1%eth0: the scope is not part of the address
    except ValueError:
        return False
    if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
        ip = ip.ipv4_mapped   # ::ffff:127.0.0.1
    return ip.is_loopback   # 127.0.0.0/8 (RFC 1122), ::1 (RFC 4291)


def check_loopback(address):
    """(loopback, why) with the rule of io/net.h (the C++ server and CLI):
    a unix socket is loopback; otherwise every host of the address must
    resolve (getaddrinfo) and EVERY address it resolves to must be loopback
    (127.0.0.0/8, ::1, ::ffff:127.0.0.0/104). A name is judged by what it
    resolves to, never by how it is spelt: `127.plant.example` that does not
    resolve, or resolves to 10.20.0.5, is not loopback; `localhost` is when
    the hosts file says so. An empty host (":50051") or a wildcard is not.
    `why` says what the address is ("resolves to 127.0.0.1", "does not
    resolve (...)") for messages."""
    for scheme in ("unix:", "unix-abstract:"):
        if address.startswith(scheme):
            return True, "is a unix socket"
    rest = address
    if rest.startswith("ipv4:") or rest.startswith("ipv6:"):
        hosts = [_host_of(item) for item in rest[5:].split(",")]   # gRPC's literal address lists
    else:
        if rest.startswith("dns:"):
            rest = rest[4:]
            if rest.startswith("//"):   # dns://[AUTHORITY]/HOST:PORT
                slash = rest.find("/", 2)
                rest = rest[slash + 1:] if slash >= 0 else ""
        hosts = [_host_of(rest)]
    resolved = []
    loopback = True
    for host in hosts:
        if not host:
            return False, "has no host (every interface)"
        try:
            infos = socket.getaddrinfo(host, None, type=socket.SOCK_STREAM)
        except (socket.gaierror, UnicodeError) as e:
            return False, f"does not resolve ({host!r}: {getattr(e, 'strerror', None) or e})"
        for info in infos:
            a = info[4][0]
            if a not in resolved:
                resolved.append(a)
            loopback = loopback and _is_loopback_ip(a)
    if not resolved:
        return False, "resolves to nothing"
    return loopback, "resolves to " + " and ".join(resolved)


def is_loopback(address):
    """check_loopback(address)[0]: every address it resolves to is loopback."""
    return check_loopback(address)[0]


def _read(path, flag):
    try:
        with open(path, "rb") as f:
            return f.read()
    except OSError as e:
        raise RuntimeError(f"{flag} {path}: cannot read ({e.strerror})") from None


def verify_table_json(data):
    """Recomputes CRC-32 and SHA-256 of a `fluxcal.table.v2` (or v1) JSON export from
    its parsed values (docs/tables.md, "Payload": every axis, then every
    output, as little-endian binary64) and compares them with the file's.
    Returns (crc32_hex, sha256_hex); raises ValueError naming the field that
    disagrees."""
    import json
    doc = json.loads(data)
    payload = b"".join(struct.pack("<%dd" % len(a["values"]), *a["values"])
                       for a in doc["axes"] + doc["outputs"])
    crc = "%08x" % (zlib.crc32(payload) & 0xffffffff)
    sha = hashlib.sha256(payload).hexdigest()
    # fluxcal.table.v2 names them payload_crc32 / payload_sha256 (v1: crc32
    # / sha256); either way they are over the values, not the file.
    key_crc = "payload_crc32" if "payload_crc32" in doc else "crc32"
    key_sha = "payload_sha256" if "payload_sha256" in doc else "sha256"
    if crc != doc[key_crc]:
        raise ValueError(f"{key_crc}: file says {doc[key_crc]}, values give {crc}")
    if sha != doc[key_sha]:
        raise ValueError(f"{key_sha}: file says {doc[key_sha]}, values give {sha}")
    return crc, sha


class Client:
    """One channel to `fluxcal serve` and the calls an engineer's script or a
    station needs. Every method raises FluxcalError on a failed RPC."""

    def __init__(self, address, ca=None, cert=None, key=None, token=None, token_file=None, insecure=False,
                 gen_dir=None, proto_dir=DEFAULT_PROTO_DIR, timeout_s=120.0):
        if (cert is None) != (key is None):
            raise RuntimeError("cert and key go together (mutual TLS)")
        self.address = server_target(address)
        if token_file:
            # The first line, as the C++ client reads --token-file.
            token = _read(token_file, "token_file").decode("utf-8").splitlines()[0].strip()
        # Loopback by what the address resolves to, every address of it
        # (check_loopback, the rule of io/net.h).
        loopback, why = check_loopback(self.address)
        tls = bool(ca or cert or (not insecure and not loopback))
        if token and not tls and not loopback:
            # A bearer token is a password: never in clear off this
            # machine, not even with insecure=True (cli/support_remote.cc).
            raise RuntimeError(f"token: tokens need TLS off loopback; {self.address} {why}, so the token is not "
                               f"sent in plaintext (drop insecure=True and pass ca=)")
        self.pb, rpc = load_stubs(gen_dir, proto_dir)
        self.timeout_s = timeout_s
        options = [("grpc.max_receive_message_length", 64 << 20)]
        if tls:
            creds = grpc.ssl_channel_credentials(
                root_certificates=_read(ca, "ca") if ca else None,
                private_key=_read(key, "key") if key else None,
                certificate_chain=_read(cert, "cert") if cert else None)
            self.channel = grpc.secure_channel(self.address, creds, options=options)
        else:
            self.channel = grpc.insecure_channel(self.address, options=options)
        # Per-call metadata rather than call credentials: grpcio attaches
        # call credentials only to TLS channels, and a loopback server with
        # --auth takes tokens over plaintext too.
        self._metadata = (("authorization", f"Bearer {token}"),) if token else ()
        self.stub = rpc.CalibrationServiceStub(self.channel)

    def close(self):
        self.channel.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def wait_ready(self, timeout_s=20.0):
        """Blocks until the channel connects (a server just started).
        Raises ServerUnreachableError when nothing answers within
        timeout_s."""
        try:
            grpc.channel_ready_future(self.channel).result(timeout=timeout_s)
        except grpc.FutureTimeoutError:
            raise ServerUnreachableError("connect", "", grpc.StatusCode.UNAVAILABLE,
                                         f"no answer within {timeout_s:g} s",
                                         _unreachable_hint(self.address)) from None

    def _call(self, name, serial, method, request):
        try:
            return method(request, timeout=self.timeout_s, metadata=self._metadata)
        except grpc.RpcError as e:
            if e.code() == grpc.StatusCode.UNAVAILABLE:
                raise ServerUnreachableError(name, serial, e.code(), e.details(),
                                             _unreachable_hint(self.address)) from None
            raise FluxcalError(name, serial, e.code(), e.details()) from None

    def ingest_hf_results(self, serial, points, motor=None, station_id="", idempotency_key=""):
        """Streams one run of identified HF points for `serial`, one message
        per point. `points`: dicts with HfPoint's fields (point_id, id_a,
        iq_a, ld_h, lq_h, optional ldq_h, *_std, temperature_c, reliable;
        `reliable` True when absent: say False for a point the bench's
        identification flagged).
        `motor` ({pole_pairs, rs_ohm, psi_pm_wb}) is required for a serial the
        store does not know yet. Returns IngestHfResultsResponse (accepted,
        points_sha256, run_id, replayed).

        The stream declares its end (end_follows, then a last message with
        the count and hf_points_sha256 of the points), so the service refuses
        it whole if a message is lost or corrupted on the way; and the
        reply's count and digest of what the service stored must equal what
        was sent, or StoredNotSentError is raised. An invalid point fails the
        whole stream (FluxcalError, INVALID_ARGUMENT naming message, point
        and field); nothing is stored then. A run whose points are all
        marked unreliable is sent with an UnreliablePointsWarning (its fit
        will fail the verdict)."""
        pb = self.pb
        sent = [pb.HfPoint(**{"reliable": True, **p}) for p in points]
        if sent and not any(p.reliable for p in sent):
            warnings.warn(f"IngestHfResults {serial}: all {len(sent)} points are marked reliable=False; the service "
                          f"stores them and the fit will fail its verdict (a majority of unreliable points)",
                          UnreliablePointsWarning, stacklevel=2)
        first = pb.IngestHfResultsRequest(serial=serial, station_id=station_id, idempotency_key=idempotency_key,
                                          end_follows=True)
        if motor is not None:
            first.motor.CopyFrom(pb.MotorInfo(**motor))
        digest = hf_points_sha256(sent)
        end = pb.IngestHfResultsRequest(end=pb.StreamEnd(messages=len(sent) + 2, count=len(sent), sha256=digest))

        def messages():
            yield first
            for p in sent:
                yield pb.IngestHfResultsRequest(points=[p])
            yield end

        r = self._call("IngestHfResults", serial, self.stub.IngestHfResults, messages())
        if r.accepted != len(sent):
            raise StoredNotSentError(f"IngestHfResults {serial}: the service stored {r.accepted} points, "
                                     f"this client sent {len(sent)} (run {r.run_id})")
        if r.points_sha256 != digest:
            raise StoredNotSentError(f"IngestHfResults {serial}: SHA-256 of the points: the service's over what it "
                                     f"stored is {r.points_sha256 or 'missing'}, this client's over what it sent is "
                                     f"{digest} (run {r.run_id})")
        return r

    def fit(self, serial, model="auto"):
        """Fits the serial's latest run; returns FitResponse (calibration, pass)."""
        return self._call("Fit", serial, self.stub.Fit, self.pb.FitRequest(serial=serial, model=model))

    def get_calibration(self, serial, version=0):
        """CalibrationRecord of `version` (0: the latest); calibration_json is
        the fluxcal.calibration.v1 document `fluxcal query` reads."""
        return self._call("GetCalibration", serial, self.stub.GetCalibration,
                          self.pb.GetCalibrationRequest(serial=serial, version=version))

    def query_flux(self, serial, points, version=0):
        """FluxValue per (id_a, iq_a): psi_d_wb, psi_q_wb, Ldd/Lqq/Ldq, apparent
        inductances, torque_nm, with standard deviations."""
        req = self.pb.QueryFluxRequest(serial=serial, version=version,
                                       points=[self.pb.OperatingPoint(id_a=i, iq_a=q) for i, q in points])
        return list(self._call("QueryFlux", serial, self.stub.QueryFlux, req).values)

    def export_table(self, serial, table="mtpa", fmt="csv", points=0, version=0, **limits):
        """ExportTableResponse: data (the file's bytes), crc32, sha256, version,
        verdict, cells, clamped_cells. `limits`: speed_points, speed_max_rpm,
        i_max_a, udc_v, rs_ohm (0 or absent: the calibration's; fw, mtpv and
        envelope need a Udc from somewhere), allow_clamped, generating (the
        generating envelope, table="envelope" only), udc_axis_v (a list of
        DC-link voltages: one table per voltage in the reply's udc_tables,
        each with udc_v, file_name, data, crc32, sha256; not with udc_v).
        `table`: mtpa, mtpv, fw or envelope."""
        req = self.pb.ExportTableRequest(serial=serial, version=version, table=table, format=fmt, points=points,
                                         **limits)
        return self._call("ExportTable", serial, self.stub.ExportTable, req)

    def diagnose(self, serial):
        """DiagnoseResponse of the serial's latest stored raw recording."""
        return self._call("Diagnose", serial, self.stub.Diagnose, self.pb.DiagnoseRequest(serial=serial))
