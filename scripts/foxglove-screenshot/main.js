// Mounts @foxglove/studio-base's App with an in-memory layout store holding layout.json.
(async () => {
  const S = self;
  const e = React.createElement;
  const listeners = new Map();
  const values = new Map();
  const appConfiguration = {
    get: (k) => values.get(k),
    set: async (k, v) => { values.set(k, v); (listeners.get(k) || []).forEach((cb) => cb(v)); },
    addChangeListener: (k, cb) => listeners.set(k, [...(listeners.get(k) || []), cb]),
    removeChangeListener: (k, cb) => listeners.set(k, (listeners.get(k) || []).filter((x) => x !== cb)),
  };
  const data = await (await fetch("layout.json")).json();
  const now = new Date().toISOString();
  const store = new Map();
  const ns = (n) => { if (!store.has(n)) store.set(n, new Map([["forcecell", {
    id: "forcecell", name: "forcecell", permission: "CREATOR_WRITE",
    baseline: { data, savedAt: now }, working: undefined, syncInfo: undefined }]])); return store.get(n); };
  const layoutStorage = {
    list: async (n) => [...ns(n).values()],
    get: async (n, id) => ns(n).get(id),
    put: async (n, l) => { ns(n).set(l.id, l); return l; },
    delete: async (n, id) => { ns(n).delete(id); },
    importLayouts: async () => {},
    migrateUnnamespacedLayouts: async () => {},
  };
  localStorage.setItem("studio.profile-data", JSON.stringify({ currentLayoutId: "forcecell" }));
  if (S.initI18n) await S.initI18n();
  const dataSources = [
    new S.FoxgloveWebSocketDataSourceFactory(),
    new S.McapLocalDataSourceFactory(),
    new S.RemoteDataSourceFactory(),
  ];
  const root = ReactDOM.createRoot(document.getElementById("root"));
  root.render(e(S.App, {
    deepLinks: [window.location.href],
    appConfiguration, dataSources, layoutStorage, extensionLoaders: [],
    enableLaunchPreferenceScreen: false, enableGlobalCss: true,
  }));
})().catch((err) => { document.body.insertAdjacentHTML("beforeend", "<pre id=err>" + err.stack + "</pre>"); console.error(err); });
