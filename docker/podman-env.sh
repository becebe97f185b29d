# Sourced by docker/*.sh: podman settings this kind of machine needs (../shared/PLATFORM.md):
# runtime runc and no default ulimits (the sandbox refuses raising them), through a
# containers.conf of our own passed in CONTAINERS_CONF, so the host's podman config is untouched.
# On a machine where podman works as it is, CLOUDCAST_PODMAN_CONF=none leaves podman alone.
if [ "${CLOUDCAST_PODMAN_CONF:-}" != none ]; then
  _cc_conf_dir=${XDG_RUNTIME_DIR:-/tmp}/cloudcast-podman
  mkdir -p "$_cc_conf_dir"
  cat >"$_cc_conf_dir/containers.conf" <<'CONF'
[containers]
default_ulimits = []

[engine]
runtime = "runc"
CONF
  export CONTAINERS_CONF="$_cc_conf_dir/containers.conf"
fi

# The mirror of this machine's apt sources (deb822 .sources files first, then sources.list), so
# that no host is written into the project.
apt_mirror() {
  local uri=""
  for f in /etc/apt/sources.list.d/*.sources; do
    [ -f "$f" ] || continue
    uri=$(awk '/^URIs:/ {print $2; exit}' "$f")
    [ -n "$uri" ] && break
  done
  if [ -z "$uri" ] && [ -f /etc/apt/sources.list ]; then
    uri=$(awk '$1 == "deb" { for (i = 2; i <= NF; i++) if ($i ~ /^(http|https|file):/) { print $i; exit } }' \
      /etc/apt/sources.list)
  fi
  [ -n "$uri" ] || { echo "no apt mirror found in /etc/apt/sources.list{,.d/*.sources}" >&2; return 1; }
  echo "$uri"
}
