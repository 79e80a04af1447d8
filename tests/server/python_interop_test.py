#!/usr/bin/env python3
"""Interop: a Python grpcio client, with stubs generated at test time from
the same proto, drives a real `fluxcal serve`: ingest, fit, export, query.
Usage: python_interop_test.py FLUXCAL_BINARY PROTO_DIR"""
import os
import socket
import subprocess
import sys
import tempfile
import time

import grpc


def main():
    binary, proto_dir = sys.argv[1], sys.argv[2]
    work = tempfile.mkdtemp(prefix="fluxcal_py_")
    # Debian's protoc (3.21, proto3 optional) with its grpc_python_plugin; the
    # protoc bundled in Debian's python3-grpc-tools predates proto3 optional.
    subprocess.run(["protoc", f"-I{proto_dir}", f"--python_out={work}", f"--grpc_python_out={work}",
                    "--plugin=protoc-gen-grpc_python=/usr/bin/grpc_python_plugin",
                    os.path.join(proto_dir, "fluxcal/v1/calibration.proto")], check=True)
    sys.path.insert(0, work)
    from fluxcal.v1 import calibration_pb2 as pb, calibration_pb2_grpc as rpc

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    db = os.path.join(work, "py.db")
    server = subprocess.Popen([binary, "serve", "--db", db, "--listen", f"127.0.0.1:{port}"],
                              stderr=subprocess.PIPE)
    try:
        channel = grpc.insecure_channel(f"127.0.0.1:{port}")
        grpc.channel_ready_future(channel).result(timeout=20)
        stub = rpc.CalibrationServiceStub(channel)

        def requests():
            yield pb.IngestHfResultsRequest(serial="IPM-PY-1", station_id="py",
                                            motor=pb.MotorInfo(pole_pairs=4, rs_ohm=0.011, psi_pm_wb=0.0114))
            for a in range(6):
                for b in range(6):
                    iq = 20.0 * b
                    lq = 0.372e-3 / (1 + (iq / 280.0) ** 2) ** 1.5
                    yield pb.IngestHfResultsRequest(points=[pb.HfPoint(
                        point_id=f"p{6 * a + b}", id_a=-100.0 + 20 * a, iq_a=iq, ld_h=0.18e-3, lq_h=lq,
                        ld_h_std=1e-7, lq_h_std=1e-7, temperature_c=25.0, reliable=True)])

        r = stub.IngestHfResults(requests(), timeout=30)
        assert r.accepted == 36, r
        f = stub.Fit(pb.FitRequest(serial="IPM-PY-1"), timeout=60)
        assert f.calibration.version == 1, f
        q = stub.QueryFlux(pb.QueryFluxRequest(serial="IPM-PY-1", points=[pb.OperatingPoint(id_a=0, iq_a=100)]),
                           timeout=30)
        lq100 = 0.372e-3 / (1 + (100 / 280.0) ** 2) ** 1.5
        assert abs(q.values[0].lqq_h / lq100 - 1) < 0.01, q
        e = stub.ExportTable(pb.ExportTableRequest(serial="IPM-PY-1", table="mtpa", format="json", points=8),
                             timeout=60)
        assert len(e.sha256) == 64 and b'"kind": "mtpa"' in e.data, e.crc32
        # A Udc axis: one table per voltage in udc_tables, named as the CLI names its files.
        ax = stub.ExportTable(pb.ExportTableRequest(serial="IPM-PY-1", table="mtpa", format="json", points=8,
                                                    udc_axis_v=[40.0, 62.5]), timeout=60)
        assert [t.udc_v for t in ax.udc_tables] == [40.0, 62.5] and not ax.data, ax
        assert ax.udc_tables[1].file_name == "IPM-PY-1_mtpa_udc62p5v.json", ax.udc_tables[1].file_name
        assert all(len(t.sha256) == 64 and b'"kind": "mtpa"' in t.data for t in ax.udc_tables)
        for bad, field in ((dict(table="mtpa", generating=True), "generating"),
                           (dict(table="mtpa", udc_axis_v=[40.0, float("nan")]), "udc_axis_v[1]")):
            try:
                stub.ExportTable(pb.ExportTableRequest(serial="IPM-PY-1", **bad), timeout=30)
                raise AssertionError("expected INVALID_ARGUMENT for %s" % field)
            except grpc.RpcError as err:
                assert err.code() == grpc.StatusCode.INVALID_ARGUMENT and field in err.details(), err
        try:
            stub.Fit(pb.FitRequest(serial="IPM-PY-NONE"), timeout=30)
            raise AssertionError("expected NOT_FOUND")
        except grpc.RpcError as err:
            assert err.code() == grpc.StatusCode.NOT_FOUND, err
        # Health checking: grpc.health.v1.Health/Check with an empty request
        # (all services) answers SERVING (field 1 = 1, bytes 08 01).
        health = channel.unary_unary("/grpc.health.v1.Health/Check",
                                     request_serializer=lambda b: b, response_deserializer=lambda b: b)
        assert health(b"", timeout=10) == b"\x08\x01", "health check not SERVING"
        # Server reflection lists the service (list_services = field 7).
        refl = channel.stream_stream("/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo",
                                     request_serializer=lambda b: b, response_deserializer=lambda b: b)
        replies = list(refl(iter([b"\x3a\x00"]), timeout=10))
        assert any(b"fluxcal.v1.CalibrationService" in r for r in replies), replies
        print("python interop: 1 passed, 0 failed")
    finally:
        server.terminate()
        server.wait(timeout=10)


if __name__ == "__main__":
    main()
