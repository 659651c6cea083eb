model two_section_bridge "PRIS H-bridge: PRBS-driven bridge voltage"
  import SI = Modelica.Units.SI;
  Modelica.Electrical.Analog.Sources.SignalVoltage Vbridge;
  Modelica.Electrical.Analog.Basic.Ground ground;
  parameter SI.Voltage vdc = 30.0 "H-bridge DC voltage (levels +-vdc)";
  parameter SI.Frequency fclk = 10000.0 "PRBS clock frequency";
  parameter Integer prbs_order = 12 "LFSR order n (period 2^n - 1 bits, n <= 30 here)";
  parameter Integer taps[:] = {12, 6, 4, 1} "maximal-length LFSR taps of this order";
  discrete Integer reg(start = integer(2^prbs_order) - 1, fixed = true) "next prbs_order output bits, first one in the most significant bit (all-ones seed)";
  discrete Integer feedback(start = 0, fixed = true);
  Modelica.Blocks.Interfaces.RealOutput v_bprbs "commanded H-bridge voltage, V";
equation
  connect(Vbridge.n, ground.p);
  v_bprbs = if mod(div(reg, integer(2^(prbs_order - 1))), 2) == 1 then vdc else -vdc;
  Vbridge.v = v_bprbs;
  when sample(1 / fclk, 1 / fclk) then  // one LFSR shift per clock: equations on pre(reg)
    feedback = mod(mod(div(pre(reg), integer(2^(taps[1] - 1))), 2) + mod(div(pre(reg), integer(2^(taps[2] - 1))), 2) + mod(div(pre(reg), integer(2^(taps[3] - 1))), 2) + mod(div(pre(reg), integer(2^(taps[4] - 1))), 2), 2);
    reg = mod(2 * pre(reg) + feedback, integer(2^prbs_order));
  end when;
  annotation(experiment(StartTime = 0.0, StopTime = 0.3, Interval = 3.125e-06));
end two_section_bridge;
