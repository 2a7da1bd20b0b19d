"""Device files from a rig's own measurements: the fits behind ``tpad-rt calibrate`` (docs/calibration.md).

API map
-------
``measurements``
    read_impedance_sweeps(path) -> [ImpedanceSweep], read_amplitudes(path) -> AmplitudeMeasurements
``impedance``
    fit_sweep(sweep) -> BvdFit: C0, L, C, R with uncertainties, or ConfigError saying why the model does not fit
``amplitude``
    fit_gamma(measurements, circuit, freq_hz=None) -> GammaFit: the one transduction factor, per-force checks
``device_file``
    build_document(fits, gamma, template, options), convert_document(path), write_device(document, out)
``plots``
    impedance_figure(sweeps, fits), amplitude_figure(measurements, circuit, fit)
"""
