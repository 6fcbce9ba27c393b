#!/usr/bin/python3
# The DISPLAY of the headless LinuxCNC run in tests/apps/linuxcnc_hal.cpp: no GUI, the test's
# plan.  LinuxCNC starts it as "<this> -ini <file>"; it reads plan.txt beside the INI:
#   on <x_mm>         machine-on positions of the input axis X, one per line
#   lo <x_mm>, hi <x_mm>, feed <mm/min>
# For each machine-on position: X goes there, the machine is switched off and on again, then X
# traverses lo -> hi -> lo while the HAL sampler records every servo period; the samples go to
# samples_<k>.txt (halsampler -t: tag, X pos-cmd, Y eoffset-request, Y eoffset, motion enabled).
# done.txt says it finished; error.txt holds what went wrong.  Exit ends LinuxCNC.
import os
import subprocess
import sys
import time
import traceback

import hal
import linuxcnc

cfgdir = os.path.dirname(os.path.abspath(sys.argv[sys.argv.index("-ini") + 1]))


def out(name, text):
    with open(os.path.join(cfgdir, name), "w") as f:
        f.write(text)


def main():
    plan = {"on": []}
    with open(os.path.join(cfgdir, "plan.txt")) as f:
        for line in f:
            key, value = line.split()
            if key == "on":
                plan["on"].append(float(value))
            else:
                plan[key] = float(value)
    ui = hal.component("errsep-ui")
    ui.ready()
    s, c = linuxcnc.stat(), linuxcnc.command()

    def wait(cond, what, timeout=30.0):
        t0 = time.time()
        while time.time() - t0 < timeout:
            s.poll()
            if cond():
                return
            time.sleep(0.005)
        raise RuntimeError("timed out waiting for " + what)

    def mdi(cmd):
        c.mode(linuxcnc.MODE_MDI)
        c.wait_complete()
        c.mdi(cmd)
        c.wait_complete()
        wait(lambda: s.interp_state == linuxcnc.INTERP_IDLE and s.queue == 0 and s.inpos,
             "'" + cmd + "' to finish")

    def machine(on):
        c.state(linuxcnc.STATE_ON if on else linuxcnc.STATE_OFF)
        c.wait_complete()
        # Machine off reads back as STATE_ESTOP_RESET (out of estop, not on).
        wait(lambda: (s.task_state == linuxcnc.STATE_ON) == on, "machine " + ("on" if on else "off"))

    c.state(linuxcnc.STATE_ESTOP_RESET)
    c.wait_complete()
    machine(True)
    c.mode(linuxcnc.MODE_MANUAL)
    c.wait_complete()
    c.home(-1)
    c.wait_complete()
    wait(lambda: all(s.homed[:3]), "homing")
    for k, x_on in enumerate(plan["on"]):
        mdi("G0 X%.4f" % x_on)
        machine(False)
        time.sleep(0.05)
        machine(True)
        wait(lambda: hal.get_value("motion.motion-enabled"), "motion enabled")
        time.sleep(0.05)
        hal.set_p("sampler.0.enable", "1")
        mdi("G1 X%.4f F%.1f" % (plan["lo"], plan["feed"]))
        mdi("G1 X%.4f F%.1f" % (plan["hi"], plan["feed"]))
        mdi("G1 X%.4f F%.1f" % (plan["lo"], plan["feed"]))
        time.sleep(0.2)  # standstill: the applied offset catches up with the request
        hal.set_p("sampler.0.enable", "0")
        depth = int(hal.get_value("sampler.0.curr-depth"))
        overruns = int(hal.get_value("sampler.0.overruns"))
        if overruns:
            raise RuntimeError("sampler overruns: %d" % overruns)
        subprocess.run(["halsampler", "-t", "-n", str(depth),
                        os.path.join(cfgdir, "samples_%d.txt" % k)], check=True, timeout=60)
    out("done.txt", "done\n")


try:
    main()
except Exception:
    out("error.txt", traceback.format_exc())
    sys.exit(1)
