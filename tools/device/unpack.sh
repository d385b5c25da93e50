# Sourced by the device scripts (run from the repository root on the device machine): unpacks what is missing
# of tools/device/pack.sh's pack, and sets R (the root), P (the pack), data (the scenes) and LD_LIBRARY_PATH.
R=$PWD; P=$R/.devpack
[ -d /tmp/devlib ] || tar xJf $P/devlib.tar.xz -C /tmp
[ -d $P/bin ] || tar xJf $P/devbin.tar.xz -C $P
export LD_LIBRARY_PATH=/tmp/devlib:/usr/local/cuda/lib64:/usr/local/cuda/targets/x86_64-linux/lib
[ -e "$R/../shared" ] || ln -s "$P/shared" "$R/../shared"
data=$R/../shared/data
