"""An independent reimplementation of ATI's DAQ F/T library (ATIDAQ) for the tests.

Written from ATIDAQ's equations (ftconfig.c: createCalibration, TTM, the unit
factors; ftrt.c: RTBias, RTConvertToFT, TempComp) in double precision, with the
standard library's XML parser: nothing of it is shared with the package, so the
ATI tests compare fsdecouple with ATIDAQ and not with itself.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET  # the test files are ours: trusted input

import numpy as np

# ATIDAQ's unit factors (ftconfig.c ForceConv, TorqueConv, DistConv, AngleConv)
FORCE_CONV = {"lb": 1.0, "lbf": 1.0, "klb": 0.001, "klbf": 0.001, "N": 4.44822161526,
              "kN": 0.00444822161526, "kg": 0.45359237, "g": 453.59237}
TORQUE_CONV = {"in-lb": 1.0, "in-lbf": 1.0, "lb-in": 1.0, "lbf-in": 1.0, "ft-lb": 0.08333333333,
               "lb-ft": 0.08333333333, "ft-lbf": 0.08333333333, "lbf-ft": 0.08333333333,
               "N-m": 0.112984829028, "Nm": 0.112984829028, "N-mm": 112.984829028,
               "Nmm": 112.984829028, "kg-cm": 1.1521246198, "kgcm": 1.1521246198,
               "kN-m": 0.000112984829028, "kNm": 0.000112984829028}
DIST_CONV = {"in": 1.0, "m": 0.0254, "cm": 2.54, "mm": 25.4, "ft": 0.08333333333}


class Atidaq:
    """ATIDAQ's createCalibration / Bias / ConvertToFT with the default (zero) user transform."""

    def __init__(self, path):
        root = ET.parse(path).getroot()
        self.n = int(root.get("NumGages"))
        cal = root.findall("Calibration")[0]
        self.force, self.torque = cal.get("ForceUnits"), cal.get("TorqueUnits")
        dist, angle = cal.get("DistUnits"), cal.get("AngleUnits") or "degrees"
        basic, self.max, names = [], [], []
        for axis in cal.iter("Axis"):
            scale = float(axis.get("scale") or "1")
            basic.append([float(v) / scale for v in axis.get("values").split()][:self.n])
            self.max.append(float(axis.get("max") or "0"))
            names.append(axis.get("Name"))
        self.names = names
        tt = [0.0] * 6
        self.bs, self.gs, self.therm, self.tc = [0.0] * self.n, [0.0] * self.n, 0.0, False
        for child in cal:
            if child.tag == "BasicTransform":
                tt = [float(child.get(k) or "0") for k in ("Dx", "Dy", "Dz", "Rx", "Ry", "Rz")]
            elif child.tag == "BiasSlope":
                self.bs, self.tc = [float(v) for v in child.get("values").split()], True
            elif child.tag == "GainSlope":
                self.gs, self.tc = [float(v) for v in child.get("values").split()], True
            elif child.tag == "Thermistor":
                self.therm = float(child.get("value"))
        self.basic = np.array(basic)
        self.basic_ttm = self._ttm(tt, dist, angle) if len(basic) == 6 else None
        self.working = self.basic_ttm @ self.basic if len(basic) == 6 else self.basic
        self.bias_vector = [0.0] * (self.n + 1)
        self.tc_bias = [0.0] * self.n

    def _ttm(self, tt, dist, angle):
        dc = TORQUE_CONV[self.torque] / (FORCE_CONV[self.force] * DIST_CONV[dist])
        ac = 1.0 if angle.startswith("deg") else 180.0 / math.pi
        sx, cx = math.sin(math.pi / 180 * tt[3] * ac), math.cos(math.pi / 180 * tt[3] * ac)
        sy, cy = math.sin(math.pi / 180 * tt[4] * ac), math.cos(math.pi / 180 * tt[4] * ac)
        sz, cz = math.sin(math.pi / 180 * tt[5] * ac), math.cos(math.pi / 180 * tt[5] * ac)
        dx, dy, dz = tt[0] * dc, tt[1] * dc, tt[2] * dc
        r = [[cy * cz, sx * sy * cz + cx * sz, sx * sz - cx * sy * cz],
             [-cy * sz, -sx * sy * sz + cx * cz, sx * cz + cx * sy * sz],
             [sy, -sx * cy, cx * cy]]
        t = [[0.0] * 6 for _ in range(6)]
        for i in range(3):
            for j in range(3):
                t[i][j] = t[3 + i][3 + j] = r[i][j]
            t[3 + i][0] = r[i][2] * dy - r[i][1] * dz
            t[3 + i][1] = r[i][0] * dz - r[i][2] * dx
            t[3 + i][2] = r[i][1] * dx - r[i][0] * dy
        return np.array(t)

    def set_tool_transform(self, vector, dist_units, angle_units="degrees"):
        """SetToolTransform: W = TTM(user) TTM(basic) B (GetMatrix)."""
        self.working = self._ttm(vector, dist_units, angle_units) @ self.basic_ttm @ self.basic

    def _temp_comp(self, g, t, i):
        return (g + self.bs[i] * (t - self.therm)) / (1 - self.gs[i] * (t - self.therm))

    def bias(self, v):
        self.bias_vector = list(v)
        self.tc_bias = [self._temp_comp(v[i], v[self.n] if self.tc else 0.0, i)
                        for i in range(self.n)]

    def convert(self, v):
        c = [self._temp_comp(v[i], v[self.n], i) - self.tc_bias[i] if self.tc
             else v[i] - self.bias_vector[i] for i in range(self.n)]
        return [sum(self.working[a][j] * c[j] for j in range(self.n))
                for a in range(len(self.working))]
