// ESLint (flat config) for the console's page: its ES modules, as the browser loads them.
// `npm ci && npm run lint` (ESLint, then tsc --checkJs against the generated types).
import js from "@eslint/js";
import globals from "globals";

export default [
  {ignores: ["node_modules/**", "lunaris/console/static/vendor/**", "**/.venv/**", ".venv/**"]},
  {
    files: ["lunaris/console/static/**/*.js"],
    languageOptions: {ecmaVersion: 2022, sourceType: "module", globals: globals.browser},
    rules: {
      ...js.configs.recommended.rules,
      "no-unused-vars": ["error", {argsIgnorePattern: "^_"}],
      "no-var": "error",
      "prefer-const": "error",
      "eqeqeq": ["error", "always"],
      "no-implicit-globals": "error",
      "no-restricted-properties": ["error",
        {property: "innerHTML", message: "build markup with lit-html templates: names are text"},
        {property: "outerHTML", message: "build markup with lit-html templates: names are text"},
        {property: "insertAdjacentHTML", message: "build markup with lit-html templates: names are text"}],
      "no-restricted-imports": ["error", {paths: [
        {name: "./vendor/lit-html/directives/unsafe-html.js", message: "names are text, never markup"}]}],
    },
  },
  {
    files: ["eslint.config.js"],
    languageOptions: {ecmaVersion: 2022, sourceType: "module", globals: globals.node},
  },
];
