model two_section_pris "PRIS arrangement: Two-section winding model, thesis Fig. 4.1, Table 4.2 driven at in"
  import SI = Modelica.Units.SI;
  parameter SI.Resistance R1 = 10.0;
  parameter SI.Resistance R2 = 10.0;
  parameter SI.Capacitance C1 = 1e-09;
  parameter SI.Capacitance C2 = 1e-09;
  parameter SI.Inductance L1 = 10.0;
  parameter SI.Inductance L2 = 100.0;
  parameter SI.Inductance M12 = 30.0;
  Modelica.Electrical.Analog.Basic.Capacitor C1_1(C = C1);
  Modelica.Electrical.Analog.Basic.Resistor R1_1(R = R1);
  Modelica.Electrical.Analog.Basic.Capacitor C2_1(C = C2);
  Modelica.Electrical.Analog.Basic.Resistor R2_1(R = R2);
  Modelica.Electrical.Analog.Sources.SignalVoltage Vbridge;
  Modelica.Electrical.Analog.Basic.Resistor Rpris(R = 31800.0);
  Modelica.Electrical.Analog.Basic.Capacitor Cpris(C = 1e-08);
  Modelica.Electrical.Analog.Basic.M_Transformer M_L1_L2(N = 2, L = {(L1), ((M12 / sqrt((L1 * L2))))*sqrt((L1)*(L2)), (L2)}) "L1, L2";
  Modelica.Electrical.Analog.Basic.Inductor Lpris(L = 2.53);
  Modelica.Electrical.Analog.Basic.Ground ground;
  parameter SI.Voltage vdc = 30.0 "H-bridge DC voltage (levels +-vdc)";
  parameter SI.Frequency fclk = 10000.0 "PRBS clock frequency";
  parameter Integer prbs_order = 12 "LFSR order n (period 2^n - 1 bits, n <= 30 here)";
  parameter Integer taps[:] = {12, 6, 4, 1} "maximal-length LFSR taps of this order";
  discrete Integer reg(start = integer(2^prbs_order) - 1, fixed = true) "next prbs_order output bits, first one in the most significant bit (all-ones seed)";
  discrete Integer feedback(start = 0, fixed = true);
  Modelica.Blocks.Interfaces.RealOutput v_in "DUT terminal voltage v(in), V";
  Modelica.Blocks.Interfaces.RealOutput i_in "current from the source RLC into the DUT terminal, A";
  Modelica.Blocks.Interfaces.RealOutput v_bprbs "commanded H-bridge voltage, V";
  Modelica.Blocks.Interfaces.RealOutput v_mid "voltage of node mid, V";
equation
  connect(C1_1.p, R1_1.p);
  connect(C1_1.p, Cpris.n);
  connect(C1_1.n, C2_1.p);
  connect(C1_1.n, R2_1.p);
  connect(C1_1.n, M_L1_L2.n[1]);
  connect(R1_1.n, M_L1_L2.p[1]);
  connect(C2_1.n, Vbridge.n);
  connect(C2_1.n, M_L1_L2.n[2]);
  connect(C2_1.n, ground.p);
  connect(R2_1.n, M_L1_L2.p[2]);
  connect(Vbridge.p, Rpris.p);
  connect(Rpris.n, Lpris.p);
  connect(Cpris.p, Lpris.n);
  v_in = C1_1.p.v;
  i_in = Lpris.i;
  v_bprbs = if mod(div(reg, integer(2^(prbs_order - 1))), 2) == 1 then vdc else -vdc;
  v_mid = C1_1.n.v;
  Vbridge.v = v_bprbs;
algorithm
  when sample(1 / fclk, 1 / fclk) then
    feedback := 0;
    for t in taps loop
      feedback := mod(feedback + mod(div(reg, integer(2^(t - 1))), 2), 2);
    end for;
    reg := mod(2 * reg + feedback, integer(2^prbs_order));
  end when;
end two_section_pris;
