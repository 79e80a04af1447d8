#!/usr/bin/env bash
# A small private CA for one plant's fluxcal service, with Debian's openssl:
# a server certificate for the service's host names/addresses and one client
# certificate per station (mutual TLS). Keys never leave this directory;
# copy server.* and clients-ca.pem to /etc/fluxcal, each station's pair to
# that station.
#   bash deploy/make-pki.sh DIR fluxcal.plant.example 10.20.0.5 station-01 station-02 flasher-01
# Then map certificate names to roles:
#   fluxcal admin add-cert --keys /etc/fluxcal/keys.json --name station-01 --role station --cn station-01
set -euo pipefail
DIR=$1; HOST=$2; IP=$3; shift 3
mkdir -p "$DIR" && cd "$DIR"
umask 077
if [ ! -f ca.key ]; then
  openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -keyout ca.key -out ca.pem \
    -days 3650 -subj "/CN=fluxcal plant CA"
fi
cp ca.pem clients-ca.pem
issue() {  # name, subject CN, extensions
  openssl req -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -keyout "$1.key" -out "$1.csr" -subj "/CN=$2"
  printf '%s\n' "$3" > "$1.ext"
  openssl x509 -req -in "$1.csr" -CA ca.pem -CAkey ca.key -CAcreateserial -out "$1.pem" -days 825 -extfile "$1.ext"
  rm -f "$1.csr" "$1.ext"
}
issue server "$HOST" "subjectAltName=DNS:$HOST,IP:$IP
extendedKeyUsage=serverAuth"
for c in "$@"; do issue "$c" "$c" "extendedKeyUsage=clientAuth"; done
echo "made: ca.pem (trust on clients: fluxcal ... --ca ca.pem), server.pem/.key, clients-ca.pem, ${*/%/.pem}" >&2
