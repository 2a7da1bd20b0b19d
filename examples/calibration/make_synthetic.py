"""Write the synthetic measurements of docs/calibration.md's worked example (the files beside this script).

    python examples/calibration/make_synthetic.py [--device NAME] [--noise 0.01] [--seed 1] [--out DIR]

A known device (default: the shipped SLG_0.56) stands in for a rig. Its circuit at five
contact forces gives impedance sweeps as an analyser would measure them (801 points
across +-5 half-power bandwidths of each force's resonance, as the paper's
HP35665A analyser sweeps), with complex noise of
``--noise`` times |Z| (standard deviation, split evenly between the real and imaginary
parts); its gamma gives plate amplitudes at 10-40 V across the actuator at each force's
resonance, with the same relative noise, as a vibrometer would. The fits should give the
device back within the noise: that is what the example shows.

Files written: ``sweeps.csv`` (freq_hz, z_real_ohm, z_imag_ohm, force_n), ``sweep_0n_polar.csv``
(freq_hz, z_abs_ohm, z_phase_deg: the 0 N sweep alone in the other form) and ``amplitudes.csv``
(force_n, voltage_v, amplitude_um, freq_hz).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from tpad_rt.device import Device
from tpad_rt.physics import electromech

FORCES_N = (0.0, 0.5, 1.0, 1.5, 2.0)
SWEEP_POINTS = 801
SWEEP_BANDWIDTHS = 5.0
VOLTS = (10.0, 20.0, 30.0, 40.0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", default="SLG_0.56", help="device file or shipped name (default SLG_0.56)")
    parser.add_argument("--noise", type=float, default=0.01, help="relative noise (default 0.01)")
    parser.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent, help="folder to write (default: here)")
    args = parser.parse_args()
    device = Device.from_file(args.device)
    rng = np.random.default_rng(args.seed)
    sweep_rows, amplitude_rows = [], []
    for force in FORCES_N:
        l_h, c_f, r_ohm = (float(value) for value in device.motional(force))
        resonance_hz = 1 / (2 * math.pi * math.sqrt(l_h * c_f))
        bandwidth_hz = resonance_hz / float(electromech.quality_factor(l_h, c_f, r_ohm))
        freq = np.linspace(resonance_hz - SWEEP_BANDWIDTHS * bandwidth_hz, resonance_hz + SWEEP_BANDWIDTHS * bandwidth_hz,
                           SWEEP_POINTS)
        z = electromech.impedance(freq, device.c0_f, l_h, c_f, r_ohm)
        z = z + args.noise * np.abs(z) * (rng.standard_normal(freq.size) + 1j * rng.standard_normal(freq.size)) / math.sqrt(2)
        sweep_rows += [(f, zi, force) for f, zi in zip(freq, z)]
        omega = 2 * math.pi * resonance_hz
        branch = abs(r_ohm + 1j * (omega * l_h - 1 / (omega * c_f)))
        for volts in VOLTS:
            amplitude_um = volts / branch / (device.gamma_n_per_v * omega) * 1e6
            amplitude_um *= 1 + args.noise * rng.standard_normal()
            amplitude_rows.append((force, volts, amplitude_um, resonance_hz))
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    header = f"# synthetic: {device.label}'s circuit, {args.noise:g} relative noise, seed {args.seed} (make_synthetic.py)\n"
    with open(out / "sweeps.csv", "w", encoding="utf-8") as stream:
        stream.write(header + "freq_hz,z_real_ohm,z_imag_ohm,force_n\n")
        stream.writelines(f"{f:.4f},{z.real:.6g},{z.imag:.6g},{force:g}\n" for f, z, force in sweep_rows)
    with open(out / "sweep_0n_polar.csv", "w", encoding="utf-8") as stream:
        stream.write(header + "freq_hz,z_abs_ohm,z_phase_deg\n")
        stream.writelines(f"{f:.4f},{abs(z):.6g},{math.degrees(np.angle(z)):.6g}\n"
                          for f, z, force in sweep_rows if force == 0.0)
    with open(out / "amplitudes.csv", "w", encoding="utf-8") as stream:
        stream.write(header + "force_n,voltage_v,amplitude_um,freq_hz\n")
        stream.writelines(f"{force:g},{volts:g},{a:.5g},{f:.4f}\n" for force, volts, a, f in amplitude_rows)
    print(f"wrote {out / 'sweeps.csv'}, {out / 'sweep_0n_polar.csv'}, {out / 'amplitudes.csv'}")


if __name__ == "__main__":
    main()
