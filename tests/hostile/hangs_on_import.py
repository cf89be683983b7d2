"""A user module whose import never finishes (for tests/hostile/impl_hangs.yaml, timeouts.ready 0.5 s)."""

import time

while True:
    time.sleep(1)
