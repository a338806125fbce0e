"""The baseline of the peer benchmark: the fault check written as a user
would write it with Python asyncua.

It subscribes to every variable of the load server (noise N_1..N_n and the
ten limit switches LS_0..LS_9), counts every data change it is given, and
raises the fault when any limit switch is open (the same check the agent's
`fault` switching function makes), naming the switch that opened.

Protocol with cellwatch-bench, one JSON object per line on stdout:
  {"ready": true, "received": n}      once every item is created
and, on each line read from stdin ("count" or "quit"):
  {"received": n, "alarms": [[switch, source_ts, detected_ts], ...]}
"""

import argparse
import asyncio
import calendar
import json
import sys
import threading
import time

from asyncua import Client, ua

SWITCH_BASE = 2_000_000
SWITCHES = 10


class Check:
    def __init__(self):
        self.received = 0
        self.switch = [True] * SWITCHES
        self.fault = False
        self.alarms = []

    def datachange_notification(self, node, val, data):
        self.received += 1
        ident = node.nodeid.Identifier
        if ident < SWITCH_BASE:
            return
        k = ident - SWITCH_BASE
        self.switch[k] = bool(val)
        fault = not all(self.switch)
        if fault and not self.fault:
            src = data.monitored_item.Value.SourceTimestamp
            stamp = calendar.timegm(src.utctimetuple()) + src.microsecond / 1e6
            self.alarms.append([k, stamp, time.time()])
        self.fault = fault


def answer(check, extra=None):
    out = {"received": check.received, "alarms": list(check.alarms)}
    if extra:
        out.update(extra)
    sys.stdout.write(json.dumps(out) + "\n")
    sys.stdout.flush()


async def main():
    p = argparse.ArgumentParser()
    p.add_argument("--endpoint", required=True)
    p.add_argument("--noise", type=int, required=True)
    p.add_argument("--publishing-ms", type=int, default=100)
    p.add_argument("--queue-size", type=int, default=10)
    args = p.parse_args()

    check = Check()
    client = Client(args.endpoint, timeout=60)
    async with client:
        ns = await client.get_namespace_index("urn:cellwatch:bench:load")
        ids = list(range(1, args.noise + 1)) + [SWITCH_BASE + k for k in range(SWITCHES)]
        sub = await client.create_subscription(args.publishing_ms, check)
        for i in range(0, len(ids), 5000):
            nodes = [client.get_node(ua.NodeId(n, ns)) for n in ids[i:i + 5000]]
            await sub.subscribe_data_change(nodes, queuesize=args.queue_size)
        sys.stdout.write(json.dumps({"ready": True, "received": check.received}) + "\n")
        sys.stdout.flush()

        done = asyncio.Event()
        loop = asyncio.get_running_loop()

        def read_stdin():
            for line in sys.stdin:
                if line.strip() == "quit":
                    break
                loop.call_soon_threadsafe(answer, check)
            loop.call_soon_threadsafe(done.set)

        threading.Thread(target=read_stdin, daemon=True).start()
        await done.wait()
        answer(check)


if __name__ == "__main__":
    asyncio.run(main())
