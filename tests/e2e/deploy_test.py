#!/usr/bin/python3
"""deploy/ as documented, run without systemd or a container engine.

Makes the plant PKI with deploy/make-pki.sh --group and the keys and health
token with `fluxcal admin add-key --group`, as docs/security.md says, then:

* deploy/fluxcal@.service: `systemd-analyze verify` (where installed), then
  its ExecStart, ExecStartPost (the health check), ExecReload (SIGHUP) and
  KillSignal, with systemd's expansion of %i, %%, $$, ${VAR} and $VAR from
  its EnvironmentFile (deploy/fluxcal.env.example);
* deploy/fluxcal.service: open on loopback as the example environment says,
  and with the example's TLS lines uncommented;
* deploy/compose.yaml (python3-yaml): a fluxcal service's command with the
  image's ENTRYPOINT, and its healthcheck test; the balancer's mounts; the
  TLS directives of deploy/nginx-grpc.conf (`nginx -t` where installed);
* deploy/Containerfile: CMD and HEALTHCHECK.

Paths are moved into a temporary directory (/etc/fluxcal, /var/lib/fluxcal,
/usr/local/bin/fluxcal -> the built binary), fixed ports to free ones, and
the compose file's PostgreSQL URL (a `db` host that does not exist here) to
a SQLite file. Run as root, the servers and health checks run as uid/gid
990 (the image's fluxcal user; setpriv) and read the private files only
through their group, as the service user does.

  /usr/bin/python3 tests/e2e/deploy_test.py build/cli/fluxcal .
"""
import os
import re
import shlex
import shutil
import signal
import socket
import stat
import subprocess
import sys
import tempfile
import time
import unittest

import yaml

FLUXCAL = os.path.abspath(sys.argv[1]) if len(sys.argv) > 1 else "build/cli/fluxcal"
REPO = os.path.abspath(sys.argv[2]) if len(sys.argv) > 2 else "."
DEPLOY = os.path.join(REPO, "deploy")
SERVICE_ID = 990   # uid and gid of the image's fluxcal user (deploy/Containerfile)
AS_ROOT = os.geteuid() == 0 and shutil.which("setpriv") is not None
if AS_ROOT and subprocess.run(["setpriv", f"--reuid={SERVICE_ID}", f"--regid={SERVICE_ID}", "--clear-groups",
                               FLUXCAL, "--version"], capture_output=True).returncode != 0:
    print(f"deploy_test: uid {SERVICE_ID} cannot run {FLUXCAL} (a private directory on its path?); the services "
          "run as this user", file=sys.stderr)
    AS_ROOT = False
GROUP = SERVICE_ID if AS_ROOT else os.getgid()
T = {}   # the temporary layout, made once


def as_service(argv):
    """argv run as the service user when we can (root), else as ourselves."""
    if AS_ROOT:
        return ["setpriv", f"--reuid={SERVICE_ID}", f"--regid={SERVICE_ID}", "--clear-groups"] + argv
    return argv


def move_paths(text):
    return (text.replace("/usr/local/bin/fluxcal", FLUXCAL)
            .replace("/etc/fluxcal", T["etc"])
            .replace("/var/lib/fluxcal", T["var"]))


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def run(argv, **kw):
    return subprocess.run(argv, capture_output=True, text=True, timeout=60, **kw)


def setUpModule():
    root = tempfile.mkdtemp(prefix="fluxcal-deploy-")
    os.chmod(root, 0o755)   # the service user must reach the files
    T.update(root=root, etc=os.path.join(root, "etc/fluxcal"), var=os.path.join(root, "var/lib/fluxcal"))
    os.makedirs(T["var"])
    os.makedirs(T["etc"])
    if AS_ROOT:
        os.chown(T["var"], SERVICE_ID, SERVICE_ID)   # StateDirectory= / the image's VOLUME
    for d in (os.path.join(root, "etc"), os.path.join(root, "var"), os.path.join(root, "var/lib")):
        os.chmod(d, 0o755)
    # docs/security.md, "Files and ownership", step by step.
    r = run(["bash", os.path.join(DEPLOY, "make-pki.sh"), "--group", str(GROUP), T["etc"], "fluxcal.plant.example",
             "10.20.0.5", "station-01"])
    assert r.returncode == 0, r.stderr
    os.chmod(T["etc"], 0o755)
    keys = os.path.join(T["etc"], "keys.json")
    old = os.umask(0o027)
    try:
        with open(os.path.join(T["etc"], "health.token"), "w") as f:
            r = subprocess.run([FLUXCAL, "admin", "add-key", "--keys", keys, "--group", str(GROUP), "--name",
                                "health", "--role", "health"], stdout=f, stderr=subprocess.PIPE, text=True)
        assert r.returncode == 0, r.stderr
        os.chown(os.path.join(T["etc"], "health.token"), -1, GROUP)
        with open(os.path.join(T["root"], "engineer.token"), "w") as f:   # a client's token: not the service's
            r = subprocess.run([FLUXCAL, "admin", "add-key", "--keys", keys, "--name", "eng-1", "--role",
                                "engineer"], stdout=f, stderr=subprocess.PIPE, text=True)
        assert r.returncode == 0, r.stderr
    finally:
        os.umask(old)


def tearDownModule():
    shutil.rmtree(T["root"], ignore_errors=True)


# --- systemd, the small part of it the units use -----------------------------

def parse_unit(path):
    """{section: [(key, value), ...]} with backslash continuations joined."""
    out, section, pending = {}, None, ""
    with open(path) as f:
        lines = f.readlines()
    for raw in lines:
        line = raw.rstrip("\n")
        if not pending and (not line.strip() or line.lstrip().startswith(("#", ";"))):
            continue
        if line.endswith("\\"):
            pending += line[:-1] + " "
            continue
        line, pending = pending + line, ""
        if line.startswith("[") and line.endswith("]"):
            section = line[1:-1]
            out.setdefault(section, [])
            continue
        key, _, value = line.partition("=")
        out[section].append((key.strip(), value.strip()))
    return out


def unit_value(unit, section, key):
    values = [v for k, v in unit[section] if k == key]
    assert len(values) == 1, f"{section}.{key}: expected one value, got {values}"
    return values[0]


def parse_env_file(path):
    env = {}
    with open(path) as f:
        lines = f.readlines()
    for line in lines:
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        k, _, v = line.partition("=")
        if len(v) >= 2 and v[0] == v[-1] and v[0] in "'\"":
            v = v[1:-1]
        env[k.strip()] = v
    return env


def systemd_argv(command, env, instance=""):
    """A unit's command line as systemd runs it (systemd.service(5),
    "Command lines"; systemd.unit(5), "Specifiers" %i and %%)."""
    command = re.sub(r"%(.)", lambda m: {"i": instance, "%": "%"}[m.group(1)], command)
    argv = []
    for word in shlex.split(command):
        word = word.replace("$$", "\0")
        m = re.fullmatch(r"\$([A-Za-z_][A-Za-z0-9_]*)", word)
        if m:   # $VAR as a word of its own: split at whitespace
            argv += env.get(m.group(1), "").split()
            continue
        word = re.sub(r"\$\{([A-Za-z_][A-Za-z0-9_]*)\}", lambda m: env.get(m.group(1), ""), word)
        argv.append(word.replace("\0", "$"))
    return argv


class Server:
    """A started `fluxcal serve` with its stderr in a file."""

    def __init__(self, argv, name):
        self.err_path = os.path.join(T["root"], name + ".err")
        self.err = open(self.err_path, "w")
        self.proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=self.err)

    def log(self):
        with open(self.err_path) as f:
            return f.read()

    def wait_for(self, text, after=0, seconds=20):
        until = time.monotonic() + seconds
        while time.monotonic() < until:
            if text in self.log()[after:]:
                return True
            if self.proc.poll() is not None:
                return False
            time.sleep(0.05)
        return False

    def stop(self, sig=signal.SIGTERM, seconds=15):
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
        try:
            return self.proc.wait(timeout=seconds)
        finally:
            self.err.close()


def list_motors(port, *flags):
    """`fluxcal list` as a client (ourselves), to check what the server takes."""
    return run([FLUXCAL, "list", "--server", f"127.0.0.1:{port}", "--prefix", "__health__"] + list(flags))


class Files(unittest.TestCase):
    def test_private_files_are_read_through_the_service_group_only(self):
        def mode(name):
            st = os.stat(os.path.join(T["etc"], name))
            return stat.S_IMODE(st.st_mode), st.st_gid
        for name in ("server.key", "keys.json", "health.token"):
            self.assertEqual(mode(name), (0o640, GROUP), name)
        self.assertEqual(mode("ca.key")[0], 0o600)
        self.assertEqual(mode("station-01.key")[0], 0o600)
        for name in ("ca.pem", "clients-ca.pem", "server.pem", "station-01.pem"):
            self.assertEqual(mode(name)[0], 0o644, name)


class TemplateUnit(unittest.TestCase):
    """deploy/fluxcal@.service: TLS, client CA, keys, a health check that
    carries the health token, reload by SIGHUP."""

    def setUp(self):
        self.unit_path = os.path.join(DEPLOY, "fluxcal@.service")
        self.unit = parse_unit(self.unit_path)
        env_file = move_paths(unit_value(self.unit, "Service", "EnvironmentFile"))
        with open(os.path.join(DEPLOY, "fluxcal.env.example")) as f:
            text = move_paths(f.read())
        with open(env_file, "w") as f:
            f.write(text)
        self.env = parse_env_file(env_file)

    def test_systemd_analyze_verify(self):
        if not shutil.which("systemd-analyze"):
            self.skipTest("systemd-analyze is not installed")
        d = os.path.join(T["root"], "units")
        os.makedirs(d, exist_ok=True)
        with open(self.unit_path) as f:
            text = f.read().replace("/usr/local/bin/fluxcal", FLUXCAL)
        with open(os.path.join(d, "fluxcal@.service"), "w") as f:
            f.write(text)
        r = run(["systemd-analyze", "verify", os.path.join(d, "fluxcal@50051.service")])
        self.assertEqual(r.returncode, 0, r.stdout + r.stderr)

    def test_starts_passes_its_health_check_reloads_and_stops(self):
        port = str(free_port())
        svc = lambda key: systemd_argv(move_paths(unit_value(self.unit, "Service", key)), self.env, port)
        start = svc("ExecStart")
        self.assertIn("--tls-cert", start)
        self.assertIn("--auth", start)
        self.assertEqual(unit_value(self.unit, "Service", "User"), "fluxcal")
        server = Server(as_service(start), "template")
        try:
            self.assertTrue(server.wait_for("listening on"), server.log())
            self.assertIn("TLS with client certificates", server.log())
            # The health check as systemd runs it: exits 0.
            r = run(as_service(svc("ExecStartPost")))
            self.assertEqual(r.returncode, 0, r.stdout + r.stderr + server.log())
            # It needs its credentials: no token, or no CA, fails.
            self.assertNotEqual(list_motors(port, "--ca", os.path.join(T["etc"], "ca.pem")).returncode, 0)
            self.assertNotEqual(list_motors(port, "--token-file", os.path.join(T["etc"], "health.token")).returncode, 0)
            # ExecReload: SIGHUP re-reads the keys; the server stays up.
            mark = len(server.log())
            env = dict(self.env, MAINPID=str(server.proc.pid))
            r = run(systemd_argv(unit_value(self.unit, "Service", "ExecReload"), env, port))
            self.assertEqual(r.returncode, 0, r.stderr)
            self.assertTrue(server.wait_for("keys reloaded", mark), server.log())
            self.assertIsNone(server.proc.poll(), "SIGHUP ended the server")
            # A revoke by root keeps the file readable by the service: the
            # engineer's token stops working, the health token goes on.
            eng = os.path.join(T["root"], "engineer.token")
            ca = os.path.join(T["etc"], "ca.pem")
            self.assertEqual(list_motors(port, "--ca", ca, "--token-file", eng).returncode, 0)
            r = run([FLUXCAL, "admin", "revoke", "--keys", os.path.join(T["etc"], "keys.json"), "--name", "eng-1"])
            self.assertEqual(r.returncode, 0, r.stderr)
            mark = len(server.log())
            run(systemd_argv(unit_value(self.unit, "Service", "ExecReload"), env, port))
            self.assertTrue(server.wait_for("keys reloaded", mark), server.log())
            self.assertNotEqual(list_motors(port, "--ca", ca, "--token-file", eng).returncode, 0)
            self.assertEqual(run(as_service(svc("ExecStartPost"))).returncode, 0, server.log())
        finally:
            sig = getattr(signal, unit_value(self.unit, "Service", "KillSignal"))
            rc = server.stop(sig, int(unit_value(self.unit, "Service", "TimeoutStopSec")))
        self.assertEqual(rc, 0, server.log())


class SingleUnit(unittest.TestCase):
    """deploy/fluxcal.service with the example environment: open on
    loopback, and with its TLS lines uncommented."""

    def run_unit(self, env_text, name, client_flags):
        unit = parse_unit(os.path.join(DEPLOY, "fluxcal.service"))
        env_file = os.path.join(T["root"], name + ".env")
        with open(env_file, "w") as f:
            f.write(env_text)
        env = parse_env_file(env_file)
        port = str(free_port())
        env["FLUXCAL_LISTEN"] = env["FLUXCAL_LISTEN"].replace("50051", port)
        env["FLUXCAL_DB"] = os.path.join(T["var"], name + ".db")
        server = Server(as_service(systemd_argv(move_paths(unit_value(unit, "Service", "ExecStart")), env)), name)
        try:
            self.assertTrue(server.wait_for("listening on"), server.log())
            r = list_motors(port, *client_flags)
            self.assertEqual(r.returncode, 0, r.stderr + server.log())
            mark = len(server.log())
            env["MAINPID"] = str(server.proc.pid)
            self.assertEqual(run(systemd_argv(unit_value(unit, "Service", "ExecReload"), env)).returncode, 0)
            time.sleep(0.2)
            self.assertIsNone(server.proc.poll(), "SIGHUP ended the server: " + server.log()[mark:])
        finally:
            rc = server.stop()
        self.assertEqual(rc, 0, server.log())
        return server.log()

    def test_example_environment_open_on_loopback(self):
        with open(os.path.join(DEPLOY, "fluxcal.env.example")) as f:
            log = self.run_unit(move_paths(f.read()), "single-open", [])
        self.assertIn("open on loopback", log)

    def test_example_environment_with_tls_and_identities(self):
        with open(os.path.join(DEPLOY, "fluxcal.env.example")) as f:
            text = move_paths(f.read())
        text = re.sub(r"^#(FLUXCAL_(LISTEN|SERVE_FLAGS)=)", r"\1", text, flags=re.M)
        log = self.run_unit(text, "single-tls", ["--ca", os.path.join(T["etc"], "ca.pem"), "--token-file",
                                                  os.path.join(T["etc"], "health.token")])
        self.assertIn("TLS with client certificates", log)
        self.assertIn("keys reloaded", log)


def containerfile():
    """ENTRYPOINT, CMD and HEALTHCHECK CMD of deploy/Containerfile (JSON form)."""
    import json
    with open(os.path.join(DEPLOY, "Containerfile")) as f:
        text = f.read().replace("\\\n", " ")
    out = {}
    for line in text.splitlines():
        m = re.match(r"(ENTRYPOINT|CMD)\s+(\[.*\])\s*$", line)
        if m:
            out[m.group(1)] = json.loads(m.group(2))
        m = re.match(r"HEALTHCHECK\s.*?CMD\s+(\[.*\])\s*$", line)
        if m:
            out["HEALTHCHECK"] = json.loads(m.group(1))
    return out


def run_until_healthy(check, attempts=50):
    for _ in range(attempts):
        r = run(check)
        if r.returncode == 0:
            return r
        time.sleep(0.2)
    return r


class Compose(unittest.TestCase):
    """deploy/compose.yaml: each fluxcal service's command (after the
    image's ENTRYPOINT) starts, and its healthcheck passes."""

    def setUp(self):
        with open(os.path.join(DEPLOY, "compose.yaml")) as f:
            self.compose = yaml.safe_load(f)

    def test_server_command_and_healthcheck(self):
        services = self.compose["services"]
        names = [n for n in services if n.startswith("fluxcal-")]
        self.assertEqual(len(names), 3)
        first = services[names[0]]
        for n in names[1:]:
            self.assertEqual(services[n], first, n)
        self.assertIn("/etc/fluxcal:/etc/fluxcal:ro", first["volumes"])
        port = str(free_port())
        db = os.path.join(T["var"], "compose.db")

        def moved(word):
            word = move_paths(word).replace("0.0.0.0:50051", "0.0.0.0:" + port)
            word = word.replace("127.0.0.1:50051", "127.0.0.1:" + port)
            return db if word.startswith("postgresql://") else word
        entrypoint = containerfile()["ENTRYPOINT"]
        argv = [moved(w) for w in entrypoint + first["command"]]
        self.assertIn("--auth", argv)
        self.assertIn("--tls-cert", argv)
        test = first["healthcheck"]["test"]
        self.assertEqual(test[0], "CMD")
        server = Server(as_service(argv), "compose")
        try:
            self.assertTrue(server.wait_for("listening on"), server.log())
            r = run_until_healthy(as_service([moved(w) for w in test[1:]]))
            self.assertEqual(r.returncode, 0, r.stderr + server.log())
        finally:
            rc = server.stop()
        self.assertEqual(rc, 0, server.log())

    def test_balancer_uses_tls_on_both_sides(self):
        balancer = self.compose["services"]["balancer"]
        self.assertIn("/etc/fluxcal:/etc/fluxcal:ro", balancer["volumes"])
        conf_mount = [v for v in balancer["volumes"] if v.startswith("./nginx-grpc.conf:")]
        self.assertEqual(len(conf_mount), 1)
        with open(os.path.join(DEPLOY, "nginx-grpc.conf")) as f:
            conf = f.read()
        directives = {}
        for line in re.sub(r"#.*", "", conf).splitlines():
            words = line.strip().rstrip(";").split()
            if words and line.strip().endswith(";"):
                directives.setdefault(words[0], []).append(words[1:])
        listen = directives["listen"][0]
        self.assertIn("ssl", listen)
        self.assertIn("http2", listen)
        self.assertTrue(all(a[0].startswith("grpcs://") for a in directives["grpc_pass"]), directives["grpc_pass"])
        self.assertEqual(directives["grpc_ssl_verify"], [["on"]])
        for key in ("ssl_certificate", "ssl_certificate_key", "grpc_ssl_trusted_certificate"):
            path = move_paths(directives[key][0][0])
            self.assertTrue(os.path.exists(path), f"{key} {path}: made by make-pki.sh")
        upstreams = [a[0].split(":")[0] for a in directives["server"]]
        self.assertEqual(sorted(upstreams), sorted(n for n in self.compose["services"] if n.startswith("fluxcal-")))
        if not shutil.which("nginx"):
            print("deploy_test: nginx is not installed; its configuration was checked directive by directive only",
                  file=sys.stderr)


class Image(unittest.TestCase):
    """deploy/Containerfile: CMD after ENTRYPOINT starts; HEALTHCHECK passes."""

    def test_cmd_and_healthcheck(self):
        c = containerfile()
        port = str(free_port())
        moved = lambda w: move_paths(w).replace(":50051", ":" + port)
        server = Server(as_service([moved(w) for w in c["ENTRYPOINT"] + c["CMD"]]), "image")
        try:
            self.assertTrue(server.wait_for("listening on"), server.log())
            r = run_until_healthy(as_service([moved(w) for w in c["HEALTHCHECK"]]))
            self.assertEqual(r.returncode, 0, r.stderr + server.log())
        finally:
            rc = server.stop()
        self.assertEqual(rc, 0, server.log())


if __name__ == "__main__":
    unittest.main(argv=[sys.argv[0], "-v"])
