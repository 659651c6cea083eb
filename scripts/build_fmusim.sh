#!/usr/bin/env bash
# Build the Reference-FMUs importer `fmusim` (an FMI 1/2/3 simulator written by the
# Modelica Association, independent of this project) against the system's libxml2,
# minizip, zlib and SUNDIALS CVODE. The tests run every shipped FMU with it when it is
# on PATH or named by PRIS_FMUSIM.
#
#   scripts/build_fmusim.sh [DEST_DIR] [SOURCE_DIR]
#
# DEST_DIR defaults to .ci-tools; SOURCE_DIR defaults to a shallow clone of
# https://github.com/modelica/Reference-FMUs at v0.0.39 (the last release with fmusim).
# Needs: gcc, git, and the Debian packages libxml2-dev libminizip-dev zlib1g-dev libsundials-dev.
set -euo pipefail
dest=${1:-.ci-tools}
src=${2:-}
mkdir -p "$dest"
dest=$(cd "$dest" && pwd)
if [ -z "$src" ]; then
  src="$dest/Reference-FMUs"
  [ -d "$src" ] || git clone -q --depth 1 --branch v0.0.39 https://github.com/modelica/Reference-FMUs "$src"
fi
cd "$src/fmusim"
# SUNDIALS 6 has no SUN_COMM_NULL (SUNContext_Create takes a null pointer there).
gcc -O1 -w -o "$dest/fmusim" -DFMUSIM_VERSION='"0.0.39"' -DSUN_COMM_NULL=NULL \
  -I. -I../include -I/usr/include/libxml2 -I/usr/include/minizip \
  ../src/FMI.c ../src/FMI1.c ../src/FMI2.c ../src/FMI3.c csv.c FMIUtil.c FMIEuler.c FMICVode.c \
  FMIModelDescription.c FMIRecorder.c FMIZip.c FMISimulation.c FMIStaticInput.c \
  FMI1CSSimulation.c FMI1MESimulation.c FMI2CSSimulation.c FMI2MESimulation.c \
  FMI3CSSimulation.c FMI3MESimulation.c fmusim.c miniunzip.c \
  ../src/structured_variable_name.yy.c ../src/structured_variable_name.tab.c \
  -lxml2 -lminizip -lz -lsundials_cvode -lsundials_nvecserial -ldl -lm
echo "$dest/fmusim"
