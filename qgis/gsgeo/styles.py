"""Symbols and labels for a gsgeo project's layers, by collection kind.

Points: a dot labelled with point_id and the 95 % error ellipse drawn to ground scale
(metres, ``RenderMetersInMapUnits``) from ellipse_major_95 / ellipse_minor_95 /
ellipse_bearing_deg; the bearing is the grid bearing the server reports (clockwise from
grid north), so on a map in another CRS it is off by the meridian convergence there.
"""

from __future__ import annotations

from qgis.core import (
    QgsEllipseSymbolLayer,
    QgsFillSymbol,
    QgsLineSymbol,
    QgsMarkerSymbol,
    QgsPalLayerSettings,
    QgsProperty,
    QgsSingleSymbolRenderer,
    QgsSymbolLayer,
    QgsTextBufferSettings,
    QgsTextFormat,
    QgsUnitTypes,
    QgsVectorLayer,
    QgsVectorLayerSimpleLabeling,
)
from qgis.PyQt.QtGui import QColor

#: Fields that name a feature, in order of preference (the first the layer has is used).
NAME_FIELDS = ("point_id", "id", "name")
#: Fields a label shows, in order of preference.
LABEL_FIELDS = (*NAME_FIELDS, "line_id", "polygon_id")


def name_field(layer: QgsVectorLayer) -> str | None:
    """The layer's field that labels its features, if any."""
    names = layer.fields().names()
    return next((f for f in LABEL_FIELDS if f in names), None)


def ellipse_layer() -> QgsEllipseSymbolLayer:
    """The 95 % error ellipse: width along grid east before turning, so the minor axis goes
    there and the major axis along the rotated y axis (the bearing)."""
    e = QgsEllipseSymbolLayer()
    e.setSymbolName("circle")
    e.setSymbolWidthUnit(QgsUnitTypes.RenderMetersInMapUnits)
    e.setSymbolHeightUnit(QgsUnitTypes.RenderMetersInMapUnits)
    e.setFillColor(QColor(0, 0, 0, 0))
    e.setStrokeColor(QColor(220, 40, 40))
    e.setStrokeWidth(0.3)
    e.setDataDefinedProperty(QgsSymbolLayer.PropertyWidth,
                             QgsProperty.fromExpression('2 * coalesce("ellipse_minor_95", 0)'))
    e.setDataDefinedProperty(QgsSymbolLayer.PropertyHeight,
                             QgsProperty.fromExpression('2 * coalesce("ellipse_major_95", 0)'))
    e.setDataDefinedProperty(QgsSymbolLayer.PropertyAngle,
                             QgsProperty.fromExpression('coalesce("ellipse_bearing_deg", 0)'))
    return e


def label(layer: QgsVectorLayer, field: str, color: QColor) -> None:
    """Label every feature with ``field`` in ``color`` on a white halo."""
    fmt = QgsTextFormat()
    fmt.setSize(9)
    fmt.setColor(color)
    buf = QgsTextBufferSettings()
    buf.setEnabled(True)
    buf.setSize(0.8)
    fmt.setBuffer(buf)
    pal = QgsPalLayerSettings()
    pal.fieldName = field
    pal.setFormat(fmt)
    layer.setLabeling(QgsVectorLayerSimpleLabeling(pal))
    layer.setLabelsEnabled(True)


def style_points(layer: QgsVectorLayer) -> None:
    sym = QgsMarkerSymbol.createSimple({"name": "circle", "color": "220,40,40",
                                        "outline_color": "255,255,255", "size": "2"})
    if "ellipse_major_95" in layer.fields().names():
        sym.appendSymbolLayer(ellipse_layer())
    layer.setRenderer(QgsSingleSymbolRenderer(sym))
    field = name_field(layer)
    if field:
        label(layer, field, QColor(150, 20, 20))


def style_check_points(layer: QgsVectorLayer) -> None:
    sym = QgsMarkerSymbol.createSimple({"name": "triangle", "color": "30,90,200",
                                        "outline_color": "255,255,255", "size": "3"})
    layer.setRenderer(QgsSingleSymbolRenderer(sym))
    field = name_field(layer)
    if field:
        label(layer, field, QColor(20, 60, 150))


def style_lines(layer: QgsVectorLayer, color: str = "240,140,0", width: str = "0.6",
                labelled: bool = True) -> None:
    layer.setRenderer(QgsSingleSymbolRenderer(
        QgsLineSymbol.createSimple({"color": color, "width": width})))
    field = name_field(layer) if labelled else None
    if field:
        label(layer, field, QColor(150, 80, 0))


def style_polygons(layer: QgsVectorLayer, color: str = "60,160,90", alpha: int = 70) -> None:
    layer.setRenderer(QgsSingleSymbolRenderer(QgsFillSymbol.createSimple(
        {"color": f"{color},{alpha}", "outline_color": color, "outline_width": "0.5"})))
    field = name_field(layer)
    if field:
        label(layer, field, QColor(20, 100, 50))


def apply_style(layer: QgsVectorLayer, kind: str) -> None:
    """Style ``layer`` as the collection kind (the part of its id after the project id)."""
    if kind == "points":
        style_points(layer)
    elif kind == "check_points":
        style_check_points(layer)
    elif kind == "lines":
        style_lines(layer)
    elif kind == "rays":
        style_lines(layer, "120,120,120", "0.2", labelled=False)
    elif kind == "polygons":
        style_polygons(layer)
    elif kind == "buildings":
        style_polygons(layer, "110,110,130")
    elif kind == "error_ellipses":
        style_polygons(layer, "220,40,40", alpha=0)
    layer.triggerRepaint()
