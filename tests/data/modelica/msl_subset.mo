package Modelica "Subset of the Modelica Standard Library 4 interfaces used by pris_cosim's exports"
  package Units
    package SI
      type Voltage = Real(unit = "V");
      type Current = Real(unit = "A");
      type Resistance = Real(unit = "Ohm");
      type Capacitance = Real(unit = "F");
      type Inductance = Real(unit = "H");
      type Frequency = Real(unit = "Hz");
    end SI;
  end Units;
  package Blocks
    package Interfaces
      connector RealInput = input Real;
      connector RealOutput = output Real;
    end Interfaces;
  end Blocks;
  package Electrical
    package Analog
      package Interfaces
        connector Pin
          Real v;
          flow Real i;
        end Pin;
        partial model OnePort
          Real v;
          Real i;
          Pin p;
          Pin n;
        equation
          v = p.v - n.v;
          0 = p.i + n.i;
          i = p.i;
        end OnePort;
      end Interfaces;
      package Basic
        model Ground
          Interfaces.Pin p;
        equation
          p.v = 0;
        end Ground;
        model Resistor
          extends Interfaces.OnePort;
          parameter Real R;
        equation
          v = R * i;
        end Resistor;
        model Capacitor
          extends Interfaces.OnePort(v(start = 0, fixed = true));
          parameter Real C;
        equation
          i = C * der(v);
        end Capacitor;
        model Inductor
          extends Interfaces.OnePort(i(start = 0, fixed = true));
          parameter Real L;
        equation
          L * der(i) = v;
        end Inductor;
        model M_Transformer
          parameter Integer N = 3;
          parameter Real L[div(N * (N + 1), 2)];
          Real v[N];
          Real i[N](each start = 0, each fixed = true);
          Interfaces.Pin p[N];
          Interfaces.Pin n[N];
        protected
          parameter Real Lm[N, N] = {{L[if r <= c then (r - 1) * N - div((r - 1) * (r - 2), 2) + c - r + 1
                                        else (c - 1) * N - div((c - 1) * (c - 2), 2) + r - c + 1]
                                      for c in 1:N} for r in 1:N};
        equation
          for k in 1:N loop
            v[k] = p[k].v - n[k].v;
            0 = p[k].i + n[k].i;
            i[k] = p[k].i;
          end for;
          v = Lm * der(i);
        end M_Transformer;
      end Basic;
      package Sources
        model SignalVoltage
          Interfaces.Pin p;
          Interfaces.Pin n;
          Modelica.Blocks.Interfaces.RealInput v;
          Real i;
        equation
          v = p.v - n.v;
          0 = p.i + n.i;
          i = p.i;
        end SignalVoltage;
        model SignalCurrent
          Interfaces.Pin p;
          Interfaces.Pin n;
          Modelica.Blocks.Interfaces.RealInput i;
          Real v;
        equation
          v = p.v - n.v;
          0 = p.i + n.i;
          i = p.i;
        end SignalCurrent;
        model ConstantVoltage
          parameter Real V = 0;
          Interfaces.Pin p;
          Interfaces.Pin n;
        equation
          V = p.v - n.v;
          0 = p.i + n.i;
        end ConstantVoltage;
      end Sources;
    end Analog;
  end Electrical;
end Modelica;
