#!/usr/bin/env bash
# Re-vendors the web page's third-party files from the npm registry (run by hand, never at run time):
#   three.min.js     three.js, only the classes viewer.js uses + OrbitControls, one minified ES module (esbuild)
#   swagger-ui-*     Swagger UI's files for /docs (app/api/routes/docs.py), as swagger-ui-dist ships them
# with their licences beside them. Needs node + npm; works in a temporary folder (no node_modules here).
set -euo pipefail
THREE=${THREE:-0.187.0}
SWAGGER=${SWAGGER:-5.35.0}
ESBUILD=${ESBUILD:-0.28.2}
here=$(cd "$(dirname "$0")" && pwd)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cd "$tmp"
npm install --silent --no-save --no-package-lock "three@$THREE" "swagger-ui-dist@$SWAGGER" "esbuild@$ESBUILD"
cat > entry.js <<'JS'
export {
  AmbientLight, BufferAttribute, BufferGeometry, Color, DirectionalLight, DoubleSide, Group, HemisphereLight, Mesh,
  MeshLambertMaterial, PerspectiveCamera, Points, PointsMaterial, Scene, Vector3, WebGLRenderer,
} from "three";
export { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";
JS
{
  echo "/* three.js r${THREE#0.} (MIT, see three.LICENSE): the classes app/api/static/viewer.js uses + OrbitControls,"
  echo "   bundled from npm three@$THREE by app/api/static/vendor/update.sh (esbuild $ESBUILD) */"
  ./node_modules/.bin/esbuild entry.js --bundle --format=esm --minify --legal-comments=none --log-level=warning
} > "$here/three.min.js"
cp node_modules/three/LICENSE "$here/three.LICENSE"
sw=node_modules/swagger-ui-dist
cp "$sw/swagger-ui-bundle.js" "$sw/swagger-ui.css" "$sw/favicon-32x32.png" "$here/"
cp "$sw/LICENSE" "$here/swagger-ui.LICENSE"
cp "$sw/NOTICE" "$here/swagger-ui.NOTICE"
cp "$sw/swagger-ui-bundle.js.LICENSE.txt" "$here/swagger-ui-bundle.js.LICENSE.txt"
# the bundle's last line points at a .map we do not ship: drop it (a 404 in the browser's console otherwise)
sed -i "/^\/\/# sourceMappingURL=/d" "$here/swagger-ui-bundle.js"
sed -i "s|/\*# sourceMappingURL=[^*]*\*/||" "$here/swagger-ui.css"
echo "vendored three@$THREE, swagger-ui-dist@$SWAGGER into $here"
