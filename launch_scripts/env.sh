# shellcheck shell=bash
# Source me (bash or zsh):   source launch_scripts/env.sh
# Activates the project's .venv (made by launch_scripts/setup.sh; another one if SORTING_LINE_VENV names it,
# as setup.sh takes it) and sets the ROS 2 environment the
# project uses without a ROS install:
#   RMW_IMPLEMENTATION=rmw_fastrtps_cpp          the only RMW in the wheels (asking for cyclonedds kills rclpy)
#   FASTRTPS_DEFAULT_PROFILES_FILE=<this dir>/fastdds_profile.xml   100 ms writer heartbeat
#   ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST      nothing discovered beyond this host; to reach other
#                                                hosts export ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET afterwards
#   PATH=<repo>/target/release:$PATH             the `sorting_line` binary (release build, made by setup.sh)
# ROS_DOMAIN_ID is left to the caller (tests should pick their own).
# Nothing here is needed just to import rclpy / sorting_line_interfaces from .venv/bin/python.

if [ -n "${BASH_VERSION:-}" ]; then
  _sl_env_file="${BASH_SOURCE[0]}"
elif [ -n "${ZSH_VERSION:-}" ]; then
  eval '_sl_env_file="${(%):-%x}"'
else
  _sl_env_file="$0"
fi
_sl_scripts="$(cd "$(dirname "$_sl_env_file")" && pwd)"
_sl_root="$(dirname "$_sl_scripts")"
_sl_venv="${SORTING_LINE_VENV:-$_sl_root/.venv}"

if [ ! -f "$_sl_venv/bin/activate" ]; then
  echo "env.sh: $_sl_venv missing; run launch_scripts/setup.sh first" >&2
else
  # shellcheck disable=SC1091
  . "$_sl_venv/bin/activate"
fi

export RMW_IMPLEMENTATION=rmw_fastrtps_cpp
export FASTRTPS_DEFAULT_PROFILES_FILE="$_sl_scripts/fastdds_profile.xml"
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
if [ ! -x "$_sl_root/target/release/sorting_line" ]; then
  echo "env.sh: $_sl_root/target/release/sorting_line missing; run launch_scripts/setup.sh first" >&2
fi
case ":$PATH:" in
  *":$_sl_root/target/release:"*) ;;
  *) export PATH="$_sl_root/target/release:$PATH" ;;
esac

unset _sl_env_file _sl_scripts _sl_root _sl_venv
