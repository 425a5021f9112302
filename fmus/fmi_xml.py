"""The model description an FMU's build writes (:class:`ModelDescriptionXml`, a part of
:class:`ipcosim.fmus.fmi.FmuBase`): pythonfmu's, plus units, unit definitions, the default experiment
and the true model structure."""
from __future__ import annotations

from typing import Iterable
from xml.etree.ElementTree import Element, SubElement

from ipcosim.fmus.experiment import default_experiment
from ipcosim.fmus.fmi_declare import parse_unit
from ipcosim.fmus.fmi_errors import FmuError


class ModelDescriptionXml:
    """``to_xml`` of :class:`ipcosim.fmus.fmi.FmuBase`, which pythonfmu's builder calls."""

    # --- modelDescription.xml ----------------------------------------------------------------

    def to_xml(self, model_options: dict[str, str] = dict()) -> Element:  # noqa: B006 -- pythonfmu's signature
        """pythonfmu's model description plus units, unit definitions and the true model structure."""
        root = super().to_xml(model_options)
        self._add_default_experiment(root)
        self._add_units(root)
        old = root.find("ModelStructure")
        if old is not None:
            root.remove(old)
        ms = SubElement(root, "ModelStructure")
        index = {info.name: info.value_reference + 1 for info in self.info.values()}
        self._add_outputs(ms, index)
        self._add_initial_unknowns(ms, index)
        return root

    def _add_default_experiment(self, root: Element) -> None:
        """``DefaultExperiment`` (:func:`default_experiment`) before ``ModelVariables``, unless the
        class declares its own."""
        if root.find("DefaultExperiment") is not None:
            return
        period = None
        for sv in root.iter("ScalarVariable"):
            real = sv.find("Real")
            if sv.get("name") == "sample_period" and real is not None and real.get("start"):
                period = float(real.get("start"))
        at = list(root).index(root.find("ModelVariables"))
        root.insert(at, Element("DefaultExperiment", default_experiment(period)))

    def _add_units(self, root: Element) -> None:
        """Each Real variable's ``unit`` attribute, and the ``UnitDefinitions`` after ``CoSimulation``."""
        units: dict[str, dict[str, int]] = {}
        for sv in root.iter("ScalarVariable"):
            info = self.info.get(sv.get("name"))
            if info is None or info.unit is None:
                continue
            real = sv.find("Real")
            if real is not None:
                real.set("unit", info.unit)
                units[info.unit] = parse_unit(info.unit)
        if units:
            ud = Element("UnitDefinitions")
            for name in sorted(units):
                u = SubElement(ud, "Unit", {"name": name})
                SubElement(u, "BaseUnit", {b: str(e) for b, e in units[name].items()})
            children = list(root)
            pos = next(k for k, c in enumerate(children) if c.tag == "CoSimulation") + 1
            root.insert(pos, ud)

    def _add_outputs(self, ms: Element, index: dict[str, int]) -> None:
        """``ModelStructure/Outputs``: each output with the inputs it depends on directly (``depends_on``)."""
        inputs = [i.name for i in self.info.values() if i.causality == "input"]
        outputs = sorted((i for i in self.info.values() if i.causality == "output"), key=lambda i: index[i.name])
        if not outputs:
            return
        node = SubElement(ms, "Outputs")
        for info in outputs:
            deps = info.depends_on or ()
            for d in deps:
                if d not in inputs:
                    raise FmuError(f"{type(self).__name__}.{info.name}: depends_on {d!r} is not an input")
            attrib = {"index": str(index[info.name]), "dependencies": _indices(deps, index)}
            if deps and info.depends_kind:
                attrib["dependenciesKind"] = " ".join([info.depends_kind] * len(deps))
            SubElement(node, "Unknown", attrib)

    def _add_initial_unknowns(self, ms: Element, index: dict[str, int]) -> None:
        """``ModelStructure/InitialUnknowns``: calculated outputs and parameters with what determines them at
        initialization (``initial_depends_on``: inputs and exact parameters; absent = all of them)."""
        knowns = [i.name for i in self.info.values()
                  if i.causality == "input" or (i.causality == "parameter" and i.initial == "exact")]
        unknowns = sorted((i for i in self.info.values()
                           if (i.causality == "output" and i.initial in ("calculated", "approx"))
                           or i.causality == "calculatedParameter"), key=lambda i: index[i.name])
        if not unknowns:
            return
        node = SubElement(ms, "InitialUnknowns")
        for info in unknowns:
            attrib = {"index": str(index[info.name])}
            if info.initial_depends_on is not None:
                for d in info.initial_depends_on:
                    if d not in knowns:
                        raise FmuError(f"{type(self).__name__}.{info.name}: initial_depends_on {d!r} is "
                                       "not an input or an exact parameter")
                attrib["dependencies"] = _indices(info.initial_depends_on, index)
            SubElement(node, "Unknown", attrib)


def _indices(names: Iterable[str], index: dict[str, int]) -> str:
    return " ".join(str(i) for i in sorted(index[n] for n in names))
