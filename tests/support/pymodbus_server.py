#!/usr/bin/python3
"""A Modbus TCP server that was not written here (Debian's python3-pymodbus 3.0), for errsep's
driver tests.  The values are encoded by pymodbus's own BinaryPayloadBuilder, so errsep's
decoder is checked against an independent implementation.

  pymodbus_server.py start --dir D   start in the background on 127.0.0.1, ephemeral port; when
                                     it serves, D/port holds the port and D/pid its pid.  If
                                     pymodbus cannot be imported, D/port holds "skip <reason>"
                                     and the exit status is still 0 (the tests then skip).
  pymodbus_server.py stop --dir D    SIGTERM the server (SIGKILL after 5 s), remove D/port, D/pid.
  pymodbus_server.py serve --dir D   serve in the foreground (what `start` runs).

Register map (unit 1; input registers and holding registers hold the same values; 0-based):
   0      int16    -1234
   1      uint16   54321
   2-3    int32    -123456789   big word order (high word first)
   4-5    int32    -123456789   little word order (low word first)
   6-7    float32  123.456      big
   8-9    float32  -0.015625    little
  10-11   int32    305419896    big
  12-13   int32    305419896    little
  14-15   float32  -98765.4375  big
  16-17   float32  98765.4375   little
  20-21   float32  0.0          holding only: a target written by the tests
  coils:  0 = 1, 1 = 0, 5 = 0 (written by the tests)
Unit 7 serves the same layout with every value negated (int16/int32/float32) so the tests can
tell units apart; uint16 is 12345 there.
"""
import argparse
import os
import signal
import sys
import time

VALUES = [  # (address, type, word order, value)
    (0, "int16", "big", -1234),
    (1, "uint16", "big", 54321),
    (2, "int32", "big", -123456789),
    (4, "int32", "little", -123456789),
    (6, "float32", "big", 123.456),
    (8, "float32", "little", -0.015625),
    (10, "int32", "big", 305419896),
    (12, "int32", "little", 305419896),
    (14, "float32", "big", -98765.4375),
    (16, "float32", "little", 98765.4375),
]


def registers(negate=False):
    from pymodbus.constants import Endian
    from pymodbus.payload import BinaryPayloadBuilder

    regs = [0] * 32
    for addr, typ, order, value in VALUES:
        b = BinaryPayloadBuilder(
            byteorder=Endian.Big, wordorder=Endian.Big if order == "big" else Endian.Little
        )
        if typ == "uint16":
            b.add_16bit_uint(12345 if negate else value)
        elif typ == "int16":
            b.add_16bit_int(-value if negate else value)
        elif typ == "int32":
            b.add_32bit_int(-value if negate else value)
        else:
            b.add_32bit_float(-value if negate else value)
        for i, r in enumerate(b.to_registers()):
            regs[addr + i] = r
    return regs


def write_atomic(path, text):
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())
    os.rename(tmp, path)


def serve(d):
    import asyncio

    from pymodbus.datastore import (
        ModbusSequentialDataBlock,
        ModbusServerContext,
        ModbusSlaveContext,
    )
    from pymodbus.server.async_io import ModbusTcpServer

    def slave(negate):
        regs = registers(negate)
        return ModbusSlaveContext(
            di=ModbusSequentialDataBlock(0, [0] * 8),
            co=ModbusSequentialDataBlock(0, [1, 0, 0, 0, 0, 0, 0, 0]),
            hr=ModbusSequentialDataBlock(0, list(regs)),
            ir=ModbusSequentialDataBlock(0, list(regs)),
            zero_mode=True,  # address 0 on the wire is element 0
        )

    context = ModbusServerContext(slaves={1: slave(False), 7: slave(True)}, single=False)

    async def main():
        server = ModbusTcpServer(context, address=("127.0.0.1", 0), allow_reuse_address=True)
        task = asyncio.create_task(server.serve_forever())
        await server.serving
        port = server.server.sockets[0].getsockname()[1]
        write_atomic(os.path.join(d, "pid"), "%d\n" % os.getpid())
        write_atomic(os.path.join(d, "port"), "%d\n" % port)
        print("listening 127.0.0.1:%d" % port, flush=True)
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        loop.add_signal_handler(signal.SIGTERM, stop.set)
        loop.add_signal_handler(signal.SIGINT, stop.set)
        await stop.wait()
        await server.server_close()
        task.cancel()

    asyncio.run(main())


def start(d):
    os.makedirs(d, exist_ok=True)
    for name in ("port", "pid"):
        try:
            os.remove(os.path.join(d, name))
        except FileNotFoundError:
            pass
    try:
        import pymodbus  # noqa: F401
        from pymodbus.server.async_io import ModbusTcpServer  # noqa: F401
    except Exception as e:  # the only case in which the tests skip
        write_atomic(os.path.join(d, "port"), "skip python3-pymodbus cannot be imported: %s\n" % e)
        print("pymodbus_server: python3-pymodbus cannot be imported: %s" % e)
        return 0
    pid = os.fork()
    if pid == 0:
        os.setsid()
        # Detach from ctest's pipes, or ctest would wait for the server to exit.
        log = os.open(os.path.join(d, "server.log"), os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        os.dup2(log, 1)
        os.dup2(log, 2)
        try:
            serve(d)
        finally:
            os._exit(0)
    deadline = time.monotonic() + 20
    port_file = os.path.join(d, "port")
    while time.monotonic() < deadline:
        if os.path.exists(port_file):
            print("pymodbus_server: started, pid %d, port %s" % (pid, open(port_file).read().strip()))
            return 0
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            sys.stderr.write("pymodbus_server: the server exited (status %d); log:\n" % status)
            sys.stderr.write(open(os.path.join(d, "server.log")).read())
            return 1
        time.sleep(0.05)
    sys.stderr.write("pymodbus_server: no port after 20 s\n")
    os.kill(pid, signal.SIGKILL)
    return 1


def stop(d):
    pid_file = os.path.join(d, "pid")
    try:
        pid = int(open(pid_file).read())
    except (FileNotFoundError, ValueError):
        print("pymodbus_server: nothing to stop")
        return 0
    try:
        os.kill(pid, signal.SIGTERM)
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline:
            os.kill(pid, 0)
            time.sleep(0.05)
        os.kill(pid, signal.SIGKILL)
        print("pymodbus_server: killed pid %d after 5 s" % pid)
    except ProcessLookupError:
        print("pymodbus_server: pid %d stopped" % pid)
    for name in ("port", "pid"):
        try:
            os.remove(os.path.join(d, name))
        except FileNotFoundError:
            pass
    return 0


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("command", choices=["start", "stop", "serve"])
    ap.add_argument("--dir", required=True, help="directory for the port, pid and log files")
    a = ap.parse_args()
    if a.command == "start":
        sys.exit(start(a.dir))
    if a.command == "stop":
        sys.exit(stop(a.dir))
    os.makedirs(a.dir, exist_ok=True)
    serve(a.dir)
