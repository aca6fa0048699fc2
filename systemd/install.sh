#!/usr/bin/env bash
# Install InkSlice as services on Raspberry Pi OS (Debian-based):
#   sudo systemd/install.sh            install, enable and start
#   systemd/install.sh --root DIR      only lay the files out under DIR (packaging, tests)
#
# What it does: a system user `inkslice` in the dialout, video, gpio and i2c
# groups; the checkout copied to /opt/inkslice and installed (not editable) into
# its venv, its dependencies at the versions and hashes of requirements.lock; the two units, the udev rules and an example /etc/inkslice/bench.json
# (never overwritten); USB stick mounting (a udev rule starting
# inkslice-stick@DEV.service, which mounts FAT/exFAT sticks under
# /media/inkslice for the inkslice user, and a polkit rule that lets that user
# unmount them after a copy); I2C switched on; udev reloaded; the services
# enabled and started; Avahi advertising the web UI (_http._tcp), the host named
# `inkslice` when it still has the image's default name, so the box answers as inkslice.local.
set -euo pipefail
SRC=$(cd "$(dirname "$0")/.." && pwd)
ROOT=""
if [ "${1:-}" = "--root" ]; then ROOT=${2:?--root needs a folder}; fi
PREFIX=/opt/inkslice

install -d "$ROOT/etc/systemd/system" "$ROOT/etc/udev/rules.d" "$ROOT/etc/inkslice" "$ROOT$PREFIX" \
           "$ROOT/usr/local/lib/inkslice" "$ROOT/etc/polkit-1/rules.d" "$ROOT/etc/avahi/services"
install -m 0644 "$SRC/systemd/inkslice-daemon.service" "$SRC/systemd/inkslice-web.service" \
                "$SRC/systemd/inkslice-stick@.service" "$ROOT/etc/systemd/system/"
install -m 0644 "$SRC/systemd/99-inkslice.rules" "$SRC/systemd/99-inkslice-usb.rules" "$ROOT/etc/udev/rules.d/"
install -m 0755 "$SRC/systemd/inkslice-stick" "$ROOT/usr/local/lib/inkslice/"
install -m 0644 "$SRC/systemd/50-inkslice-stick.rules" "$ROOT/etc/polkit-1/rules.d/"
install -m 0644 "$SRC/systemd/avahi/inkslice.service" "$ROOT/etc/avahi/services/inkslice.service"
[ -e "$ROOT/etc/inkslice/bench.json" ] || install -m 0644 "$SRC/systemd/bench.json" "$ROOT/etc/inkslice/bench.json"

# the code: a copy (not the checkout itself: a `git pull` must not change a running box)
# (./build: setuptools' staging folder; a stale one would put deleted modules into the box's wheel)
tar -C "$SRC" --exclude=.git --exclude=.venv --exclude='__pycache__' --exclude='*.egg-info' \
    --exclude=./build --exclude=./dist --exclude=.pytest_cache \
    --exclude=appliance/firmware/stepper/build --exclude=demo-out --exclude=benches/out --exclude=tests/artifacts \
    -cf - . | tar -C "$ROOT$PREFIX" -xf -

if [ -n "$ROOT" ]; then
  echo "install: files laid out under $ROOT"
  exit 0
fi

[ "$(id -u)" = 0 ] || { echo "install: run as root (sudo $0)" >&2; exit 1; }
for g in dialout video gpio i2c; do getent group "$g" >/dev/null || groupadd --system "$g"; done
if ! id inkslice >/dev/null 2>&1; then
  useradd --system --no-create-home --home-dir /var/lib/inkslice --shell /usr/sbin/nologin \
          --groups dialout,video,gpio,i2c inkslice
fi
# polkitd: the rule that lets the daemon unmount a stick; avrdude and gcc-avr: `inkslice firmware flash`
# avahi-daemon: the box on the LAN as inkslice.local, the web UI advertised as _http._tcp
apt-get install -y -qq --no-install-recommends python3-venv python3-dev polkitd avrdude gcc-avr avr-libc make \
    avahi-daemon >/dev/null
case "$(hostname)" in raspberrypi|localhost|debian) hostnamectl set-hostname inkslice
  sed -i 's/^127\.0\.1\.1.*/127.0.1.1\tinkslice/' /etc/hosts ;; esac
[ -x "$PREFIX/.venv/bin/python" ] || python3 -m venv "$PREFIX/.venv"
# the dependencies exactly as the tests ran them (versions and hashes), then the package alone
"$PREFIX/.venv/bin/python" -m pip install -q --require-hashes -r "$PREFIX/requirements.lock"
"$PREFIX/.venv/bin/python" -m pip install -q --no-deps "$PREFIX"
command -v raspi-config >/dev/null && raspi-config nonint do_i2c 0 || true
udevadm control --reload-rules
udevadm trigger --subsystem-match=tty --subsystem-match=video4linux --subsystem-match=gpio --subsystem-match=i2c-dev
systemctl daemon-reload
udevadm trigger --action=add --subsystem-match=block       # a stick already plugged in gets mounted
systemctl enable --now inkslice-daemon.service inkslice-web.service
systemctl enable avahi-daemon.service && systemctl restart avahi-daemon.service   # the name and the service file
echo "install: done. Open http://$(hostname).local:8080/ from a phone on the same network."
echo "Logs: journalctl -u inkslice-daemon -u inkslice-web -f"
