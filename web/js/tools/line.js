// The line tool (L): a polyline through measured points in the order they are picked.

import { featureTool } from "./feature.js";

export default featureTool({
  kind: "line", plural: "lines", need: 2, shortcut: "L",
  label: "Line", title: "Line from measured points (L)",
});
