// The polygon tool (P): a polygon through measured points (each once), closed by the server.

import { featureTool } from "./feature.js";

export default featureTool({
  kind: "polygon", plural: "polygons", need: 3, shortcut: "P",
  label: "Polygon", title: "Polygon from measured points (P)",
});
