"""A small SUMO network of another route than the study's, and SUMO's FCD output on it, made by real SUMO
(netconvert and sumo of the eclipse-sumo wheel) for tests/study/test_fcd_sumo.py.

Road "town" (A→B, 392.8 m after netconvert's junction cut, 50 km/h = 13.89 m/s) meets a cross road at the traffic
light B and goes on as "rural" (B→C, 80 km/h = 22.22 m/s). The light's static program (42 s green / 3 s yellow for
each road, the cross road first) runs with offset 17 s, so its phase at SUMO time t is found at (t − 17) mod 90.
Eleven vehicles: `ego` (departs at SUMO time 5 s, standing, on town → rural) and car1 … car10.
"""
from __future__ import annotations

import os
import subprocess
from pathlib import Path

NODES = """<nodes>
  <node id="A" x="0" y="0"/>
  <node id="B" x="400" y="0" type="traffic_light"/>
  <node id="C" x="1400" y="0"/>
  <node id="N" x="400" y="300"/>
  <node id="S" x="400" y="-300"/>
</nodes>
"""
EDGES = """<edges>
  <edge id="town" from="A" to="B" numLanes="1" speed="13.8889"/>
  <edge id="rural" from="B" to="C" numLanes="1" speed="22.2222"/>
  <edge id="cross_in" from="N" to="B" numLanes="1" speed="13.8889"/>
  <edge id="cross_out" from="B" to="S" numLanes="1" speed="13.8889"/>
</edges>
"""
# netconvert's own program for B (link order: cross_in→cross_out, cross_in→rural, town→cross_out, town→rural),
# given here only to set its offset
TLL = """<tlLogics>
  <tlLogic id="B" type="static" programID="0" offset="17">
    <phase duration="42" state="GGrr"/>
    <phase duration="3" state="yyrr"/>
    <phase duration="42" state="rrGG"/>
    <phase duration="3" state="rryy"/>
  </tlLogic>
</tlLogics>
"""
ROUTES = """<routes>
  <vType id="car" length="4.5" sigma="0"/>
  <route id="main" edges="town rural"/>
  <route id="cross" edges="cross_in cross_out"/>
  <vehicle id="car1" type="car" route="main" depart="0"/>
  <vehicle id="car2" type="car" route="cross" depart="1"/>
  <vehicle id="car3" type="car" route="main" depart="3"/>
  <vehicle id="ego" type="car" route="main" depart="5" departSpeed="0"/>
  <vehicle id="car4" type="car" route="cross" depart="6"/>
  <vehicle id="car5" type="car" route="main" depart="9"/>
  <vehicle id="car6" type="car" route="cross" depart="12"/>
  <vehicle id="car7" type="car" route="main" depart="15"/>
  <vehicle id="car8" type="car" route="cross" depart="20"/>
  <vehicle id="car9" type="car" route="main" depart="25"/>
  <vehicle id="car10" type="car" route="main" depart="30"/>
</routes>
"""
TLS_STATES = """<additional>
  <timedEvent type="SaveTLSStates" source="B" dest="{dest}"/>
</additional>
"""


def _run(*args: str) -> None:
    from pedas.network import sumo_home

    subprocess.run(list(args), check=True, capture_output=True, timeout=120,
                   env={**os.environ, "SUMO_HOME": str(sumo_home())})


def build(out: Path, *fcd_options: str, tls_states: bool = False) -> tuple[Path, Path]:
    """(network, FCD file) in folder `out`: netconvert builds two.net.xml, sumo runs the routes with its default
    options plus `fcd_options` and writes fcd.xml (and, with `tls_states`, the light's states to tls.xml)."""
    from pedas.network import binary

    out.mkdir(parents=True, exist_ok=True)
    for name, text in (("two.nod.xml", NODES), ("two.edg.xml", EDGES), ("two.tll.xml", TLL),
                       ("two.rou.xml", ROUTES), ("tls.add.xml", TLS_STATES.format(dest=out / "tls.xml"))):
        (out / name).write_text(text, encoding="utf-8")
    net, fcd = out / "two.net.xml", out / "fcd.xml"
    _run(str(binary("netconvert")), "-n", str(out / "two.nod.xml"), "-e", str(out / "two.edg.xml"),
         "-i", str(out / "two.tll.xml"), "-o", str(net), "--no-warnings", "true")
    extra = ["-a", str(out / "tls.add.xml")] if tls_states else []
    _run(str(binary("sumo")), "-n", str(net), "-r", str(out / "two.rou.xml"), "--fcd-output", str(fcd),
         "--no-step-log", "true", *extra, *fcd_options)
    return net, fcd
