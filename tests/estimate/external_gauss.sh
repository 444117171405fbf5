#!/bin/sh
# external_gauss.sh COLOR OUTPUT: mcpost's own gauss denoiser run as an external
# command (tests/estimate/test_external.c); $MCPOST is the mcpost executable.
exec "$MCPOST" denoise --color "$1" --denoiser gauss -o "$2"
