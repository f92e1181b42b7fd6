# Sourced before the steps of docs/DAEMON-INSTALL.md by tests/install.rs. The steps run as
# written, with the host's paths moved under $ROOT; this file plays what a temporary root cannot
# have: systemd (`systemctl`), `apt-get install` (a package must be there already) and
# `cargo build` (the test's binary is already in target/release/skillpost), and checks that
# step 4's `--check-config` writes nothing.
# Everything else (useradd, groupadd, usermod, install, strip, sed, chgrp, chmod, find, setfacl,
# setpriv, runuser, systemd-analyze) is the real command.
#
# Needs: ROOT (the temporary root), RECORD (a file: what the test must clean up).

UNIT_DIR="$ROOT/etc/systemd/system"
PIDFILE="$ROOT/emulated-systemd.pid"
JOURNAL="$ROOT/journal.log"

step() { printf '\n$ %s\n' "$*" >&2; }

cargo() { echo "(test) not run: cargo $* (target/release/skillpost is the test's binary)"; }

# The test does not install packages on the machine: each package named must be installed
# already (the test checked for its tools before it started), else the step fails, as it would
# on a host without the package and without network access.
apt-get() {
    local a pkg missing=0
    [ "$1" = install ] || { echo "(test) apt-get $* is not played" >&2; return 1; }
    for a in "${@:2}"; do
        case "$a" in -*) continue ;; esac
        pkg="$a"
        if dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q 'install ok installed'; then
            echo "(test) not run: apt-get install $pkg (installed)"
        elif [ "$pkg" = acl ] && command -v setfacl >/dev/null; then
            echo "(test) not run: apt-get install $pkg (setfacl is there)"
        else
            echo "(test) $pkg is not installed and the test installs nothing" >&2
            missing=1
        fi
    done
    return "$missing"
}

# A fresh host has no `skillpost` user; a host where it exists keeps it (and the test does not
# remove it).
useradd() {
    local name="${!#}"
    if id "$name" >/dev/null 2>&1; then
        echo "(test) user $name exists already: kept"
    else
        command useradd "$@" && echo "user $name" >>"$RECORD"
    fi
}

# Step 4's `skillpost watch --check-config` (run by the real setpriv) writes nothing anywhere:
# the listing of the whole temporary root (names, sizes, modes, times) is the same after it,
# and it does not leave /tmp/skillpost-<uid> behind.
setpriv() {
    case " $* " in
    *" --check-config "*)
        local before after rc=0 tmpd had=no
        tmpd="/tmp/skillpost-$(id -u skillpost)"
        [ ! -e "$tmpd" ] || had=yes
        before=$(ls -laR --time-style=full-iso "$ROOT" 2>&1)
        command setpriv "$@" || rc=$?
        after=$(ls -laR --time-style=full-iso "$ROOT" 2>&1)
        if [ "$had" = no ] && [ -e "$tmpd" ]; then
            echo "(test) the check made $tmpd" >&2
            return 1
        fi
        if [ "$before" != "$after" ]; then
            echo "(test) the check wrote something:" >&2
            diff <(printf '%s\n' "$before") <(printf '%s\n' "$after") >&2 || true
            return 1
        fi
        echo "(test) check-config: exit status $rc, nothing written under \$ROOT"
        return "$rc"
        ;;
    *) command setpriv "$@" ;;
    esac
}

# `skillpost status` finds the service's state file in /run/skillpost, here under $ROOT.
skillpost() { RUNTIME_DIRECTORY="$ROOT/run/skillpost" command skillpost "$@"; }

# systemd-analyze verify must print nothing about the unit.
systemd-analyze() {
    local out rc=0
    out=$(SYSTEMD_LOG_COLOR=0 command systemd-analyze "$@" 2>&1) || rc=$?
    printf '%s\n' "$out"
    if [ "$1" = verify ] && printf '%s\n' "$out" | grep -q skillpost; then
        echo "(test) systemd-analyze verify complains about the unit" >&2
        return 1
    fi
    return "$rc"
}

# The values of a unit setting in the unit and its drop-ins, in order; an empty assignment
# resets the list (as systemd does).
unit_values() {
    local key="$1" line v f
    local -a vals=()
    for f in "$UNIT_DIR/skillpost.service" "$UNIT_DIR"/skillpost.service.d/*.conf; do
        [ -f "$f" ] || continue
        while IFS= read -r line || [ -n "$line" ]; do
            case "$line" in
            "$key="*)
                v="${line#"$key="}"
                if [ -z "$v" ]; then vals=(); else vals+=("$v"); fi
                ;;
            esac
        done <"$f"
    done
    if [ "${#vals[@]}" -gt 0 ]; then printf '%s\n' "${vals[@]}"; fi
}
unit_last() { unit_values "$1" | tail -n 1; }

# What systemd does for this unit at start, as far as the test needs: ReadWritePaths= must
# exist (else 226/NAMESPACE), LogsDirectory= and RuntimeDirectory= are made for the user, the
# process runs as User=/Group= with SupplementaryGroups=, AmbientCapabilities= and UMask=,
# Environment= set,
# RUNTIME_DIRECTORY given; stdout and stderr go to the "journal". Ready (Type=notify's READY=1)
# when the state file says `running` instead of `starting`. (Not played: the sandbox, the watchdog, Type=notify.)
service_start() {
    local user group umask exec supp p env
    user=$(unit_last User)
    group=$(unit_last Group)
    umask=$(unit_last UMask)
    exec=$(unit_last ExecStart)
    supp=$(unit_values SupplementaryGroups | tr '\n' ' ')
    for p in $(unit_values ReadWritePaths); do
        case "$p" in -*) continue ;; esac
        if [ ! -e "$p" ]; then
            echo "skillpost.service: Failed at step NAMESPACE: $p: No such file or directory (status=226/NAMESPACE)" >&2
            return 1
        fi
    done
    p="$ROOT/var/log/$(unit_last LogsDirectory)"
    install -d -o "$user" -g "$group" -m "$(unit_last LogsDirectoryMode)" "$p"
    p="$ROOT/run/$(unit_last RuntimeDirectory)"
    install -d -o "$user" -g "$group" -m "$(unit_last RuntimeDirectoryMode)" "$p"
    # The user's groups (initgroups) and SupplementaryGroups=, as numbers.
    local gids caps c
    gids=$(id -G "$user" | tr ' ' ',')
    for g in $supp; do gids="$gids,$(getent group "$g" | cut -d: -f3)"; done
    # AmbientCapabilities= (CapabilityBoundingSet= the same here).
    caps=""
    for c in $(unit_values AmbientCapabilities); do
        c=$(printf '%s' "${c#CAP_}" | tr 'A-Z' 'a-z')
        caps="$caps,+$c"
    done
    caps="${caps#,}"
    local -a capargs=(--inh-caps=-all --bounding-set=-all)
    if [ -n "$caps" ]; then
        capargs=(--inh-caps="$caps" --ambient-caps="$caps" --bounding-set="-all,$caps")
    fi
    env=$(unit_values Environment | tr '\n' ' ')
    # shellcheck disable=SC2086
    (cd / && exec env $env RUNTIME_DIRECTORY="$p" setpriv --reuid="$user" --regid="$group" \
        --groups="$gids" "${capargs[@]}" -- sh -c "umask $umask && exec $exec" >>"$JOURNAL" 2>&1) &
    echo $! >"$PIDFILE"
    echo "service $!" >>"$RECORD"
    local i
    for i in $(seq 1 200); do
        if grep -q '"daemon": "running"' "$p/status.json" 2>/dev/null; then
            return 0
        fi
        if ! kill -0 "$(cat "$PIDFILE")" 2>/dev/null; then
            echo "skillpost.service: the daemon exited; journal:" >&2
            cat "$JOURNAL" >&2
            return 1
        fi
        sleep 0.05
    done
    echo "skillpost.service: not ready after 10 s" >&2
    return 1
}

systemctl() {
    case "$1" in
    daemon-reload) ;;
    enable) [ "$2" = --now ] && service_start ;;
    start | restart) service_start ;;
    reload) kill -HUP "$(cat "$PIDFILE")" && sleep 0.5 ;;
    stop) kill -TERM "$(cat "$PIDFILE")" ;;
    status)
        local summary
        summary=$(sed -n 's/^ *"summary": "\(.*\)",$/\1/p' "$ROOT/run/skillpost/status.json")
        echo "● skillpost.service - $(unit_last Description)"
        echo "     Active: active (running) (emulated by tests/install.rs)"
        echo "     Status: \"$summary\""
        ;;
    *)
        echo "(test) systemctl $* is not played" >&2
        return 1
        ;;
    esac
}
