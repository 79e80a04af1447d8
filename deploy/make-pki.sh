#!/usr/bin/env bash
# A small private CA for one plant's fluxcal service, with Debian's openssl:
# a server certificate for the service's host name and address (and
# localhost / 127.0.0.1, so a health check on the server's own host verifies
# it too) and one client certificate per station (mutual TLS).
#   bash deploy/make-pki.sh [--group GROUP] DIR HOST IP [CLIENT...]
#   bash deploy/make-pki.sh --group fluxcal /etc/fluxcal fluxcal.plant.example 10.20.0.5 station-01 flasher-01
# Files (docs/security.md, "Files and ownership"):
#   ca.key        the CA's private key: 0600, never leaves DIR (keep DIR's
#                 ca.key offline if you can; it signs new certificates)
#   ca.pem        the CA certificate: 0644; clients trust it (--ca ca.pem)
#   clients-ca.pem  the same CA, for serve --client-ca: 0644
#   server.pem    0644; server.key 0600, or 0640 in GROUP with --group, so
#                 the service user (a member of GROUP) reads it
#   NAME.pem / NAME.key  one pair per client: give each to its station
#                 (the key 0600)
# Run it as root (or as the owner of DIR); --group needs root or membership
# of GROUP. Then map certificate names to roles:
#   fluxcal admin add-cert --keys /etc/fluxcal/keys.json --group fluxcal --name station-01 --role station --cn station-01
set -euo pipefail
GROUP=""
if [ "${1:-}" = "--group" ]; then GROUP=$2; shift 2; fi
if [ $# -lt 3 ]; then
  echo "usage: make-pki.sh [--group GROUP] DIR HOST IP [CLIENT...]" >&2
  exit 2
fi
DIR=$1; HOST=$2; IP=$3; shift 3
mkdir -p "$DIR"   # on its own line: a failure stops the script (set -e ignores && lists)
cd "$DIR"
umask 077   # private keys are born 0600; public files are opened up below
if [ ! -f ca.key ]; then
  openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -keyout ca.key -out ca.pem \
    -days 3650 -subj "/CN=fluxcal plant CA" 2>/dev/null
fi
cp ca.pem clients-ca.pem
issue() {  # name, subject CN, extensions
  openssl req -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -keyout "$1.key" -out "$1.csr" \
    -subj "/CN=$2" 2>/dev/null
  printf '%s\n' "$3" > "$1.ext"
  openssl x509 -req -in "$1.csr" -CA ca.pem -CAkey ca.key -CAcreateserial -out "$1.pem" -days 825 \
    -extfile "$1.ext" 2>/dev/null
  rm -f "$1.csr" "$1.ext"
}
issue server "$HOST" "subjectAltName=DNS:$HOST,IP:$IP,DNS:localhost,IP:127.0.0.1
extendedKeyUsage=serverAuth"
for c in "$@"; do issue "$c" "$c" "extendedKeyUsage=clientAuth"; done
# Certificates are public; private keys are not.
chmod 0644 ca.pem clients-ca.pem server.pem "${@/%/.pem}"
chmod 0600 ca.key server.key "${@/%/.key}"
if [ -n "$GROUP" ]; then
  chgrp "$GROUP" server.key
  chmod 0640 server.key
fi
echo "made in $DIR: ca.pem (clients: --ca ca.pem), clients-ca.pem, server.pem, server.key${GROUP:+ (group $GROUP, 0640)}${*:+, }${*/%/.pem/.key}" >&2
