//! `pipeline.toml`: the bake settings file. Unknown keys and bad values are errors that name
//! the key and the file.
//!
//! # Which file applies
//! Like cargo with `Cargo.toml`, [`discover`] walks up from the input (a mesh file's directory,
//! or the input directory itself) to the nearest directory holding a `pipeline.toml`. The walk
//! stops at the filesystem root and at the first directory holding `.git` (a repository root,
//! whose own `pipeline.toml` still counts), so a file outside the repository never applies.
//! `--config FILE` replaces the discovered file; with neither, the embedded defaults apply.

use mres_build::settings::BakeSettings;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// The file name [`discover`] looks for.
pub const CONFIG_FILE_NAME: &str = "pipeline.toml";

/// The nearest `pipeline.toml` that applies to `input` (see the module documentation), or
/// `None` if there is none below the walk's stopping point.
pub fn discover(input: &Path) -> std::io::Result<Option<PathBuf>> {
    let start = if input.is_dir() { input } else { input.parent().unwrap_or(Path::new("")) };
    let start = if start.as_os_str().is_empty() { Path::new(".") } else { start };
    let start = start.canonicalize().map_err(|e| std::io::Error::new(e.kind(), format!("{}: {e}", start.display())))?;
    for dir in start.ancestors() {
        let candidate = dir.join(CONFIG_FILE_NAME);
        if candidate.is_file() {
            return Ok(Some(candidate));
        }
        if dir.join(".git").exists() {
            break;
        }
    }
    Ok(None)
}

/// The embedded defaults: the repository's `pipeline.toml`.
pub const DEFAULT_PIPELINE_TOML: &str = include_str!("../../../pipeline.toml");

/// A parsed `pipeline.toml`.
#[derive(Clone, Debug, Default)]
pub struct PipelineConfig {
    /// `[bake]`: settings of every bake.
    pub bake: BakeSettings,
    /// `[output]`: where results go.
    pub output: OutputConfig,
    /// `[cache]`: the content-addressed cache.
    pub cache: CacheConfig,
    /// `[[override]]`: per-asset settings, in file order; later ones win.
    pub overrides: Vec<Override>,
}

/// `[output]` section.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OutputConfig {
    /// Output directory, relative to the working directory.
    pub dir: String,
}

impl Default for OutputConfig {
    fn default() -> Self {
        OutputConfig { dir: "out".into() }
    }
}

/// `[cache]` section.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CacheConfig {
    /// Cache directory, relative to the working directory (git-ignored by default).
    pub dir: String,
    /// Whether `bake-all` uses the cache at all.
    pub enabled: bool,
}

impl Default for CacheConfig {
    fn default() -> Self {
        CacheConfig { dir: ".mres-cache".into(), enabled: true }
    }
}

/// One `[[override]]`: settings for the assets whose path (relative to the asset root, `/`
/// separators) matches `glob`.
#[derive(Clone, Debug)]
pub struct Override {
    /// The glob, e.g. `scans/**` or `**/*_hero.glb`.
    pub glob: String,
    /// The `[bake]` keys it sets.
    pub settings: toml::Table,
    matcher: globset::GlobMatcher,
}

impl Override {
    /// Whether this override applies to the asset at `relative` (path under the asset root).
    pub fn matches(&self, relative: &Path) -> bool {
        let rel: PathBuf = relative.components().collect();
        self.matcher.is_match(rel)
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConfig {
    #[serde(default)]
    bake: toml::Table,
    #[serde(default)]
    output: OutputConfig,
    #[serde(default)]
    cache: CacheConfig,
    #[serde(default, rename = "override")]
    overrides: Vec<toml::Table>,
}

/// Applies `keys` (a partial `[bake]` table) on top of `base`; unknown keys and bad values are
/// errors naming the key.
fn merge(base: &BakeSettings, keys: &toml::Table) -> Result<BakeSettings, String> {
    let mut table = toml::Table::try_from(base).map_err(|e| e.to_string())?;
    let mut settings = base.clone();
    // One key at a time, so that a type error names its key.
    for (k, v) in keys {
        if !table.contains_key(k) {
            return Err(format!("unknown key `{k}`"));
        }
        table.insert(k.clone(), v.clone());
        settings = toml::Value::Table(table.clone())
            .try_into()
            .map_err(|e: toml::de::Error| format!("`{k}` = {v}: {}", e.message()))?;
    }
    settings.check()?;
    Ok(settings)
}

impl PipelineConfig {
    /// Parses TOML text; `origin` names the file in errors.
    pub fn parse(text: &str, origin: &str) -> Result<PipelineConfig, String> {
        let raw: RawConfig = toml::from_str(text).map_err(|e| format!("{origin}: {e}"))?;
        let bake = merge(&BakeSettings::default(), &raw.bake).map_err(|e| format!("{origin}: [bake] {e}"))?;
        let mut overrides = Vec::new();
        for (i, mut table) in raw.overrides.into_iter().enumerate() {
            let where_ = format!("{origin}: [[override]] #{}", i + 1);
            let glob = match table.remove("glob") {
                Some(toml::Value::String(g)) => g,
                _ => return Err(format!("{where_}: needs glob = \"pattern\"")),
            };
            let matcher =
                globset::Glob::new(&glob).map_err(|e| format!("{where_}: glob {glob:?}: {e}"))?.compile_matcher();
            merge(&bake, &table).map_err(|e| format!("{where_} ({glob}): {e}"))?;
            overrides.push(Override { glob, settings: table, matcher });
        }
        Ok(PipelineConfig { bake, output: raw.output, cache: raw.cache, overrides })
    }

    /// Loads `path`.
    pub fn load(path: &Path) -> Result<PipelineConfig, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        PipelineConfig::parse(&text, &path.display().to_string())
    }

    /// The effective settings of the asset at `relative` (path under the asset root).
    pub fn settings_for(&self, relative: &Path) -> BakeSettings {
        let mut settings = self.bake.clone();
        for o in &self.overrides {
            if o.matches(relative) {
                // Checked when the file was parsed.
                settings = merge(&settings, &o.settings).unwrap_or(settings);
            }
        }
        settings
    }

    /// The overrides that match none of `relatives` (asset paths under the asset root).
    pub fn unmatched_overrides<'a>(&'a self, relatives: &[PathBuf]) -> Vec<&'a Override> {
        self.overrides.iter().filter(|o| !relatives.iter().any(|r| o.matches(r))).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedded_defaults_equal_code_defaults() {
        let c = PipelineConfig::parse(DEFAULT_PIPELINE_TOML, "pipeline.toml").unwrap();
        assert_eq!(c.bake, BakeSettings::default());
    }

    #[test]
    fn unknown_keys_and_bad_values_name_the_key() {
        let e = PipelineConfig::parse("[bake]\nmax_triangle = 3\n", "p.toml").unwrap_err();
        assert!(e.contains("p.toml") && e.contains("max_triangle"), "{e}");
        let e = PipelineConfig::parse("[bake]\nposition_bits = 40\n", "p.toml").unwrap_err();
        assert!(e.contains("position_bits"), "{e}");
        let e = PipelineConfig::parse("[bake]\nposition_bits = \"x\"\n", "p.toml").unwrap_err();
        assert!(e.contains("position_bits"), "{e}");
        let e = PipelineConfig::parse("[[override]]\nglob = \"a/**\"\nnormal_bits = 99\n", "p.toml").unwrap_err();
        assert!(e.contains("override") && e.contains("normal_bits"), "{e}");
        let e = PipelineConfig::parse("[cache]\ndirectory = \"x\"\n", "p.toml").unwrap_err();
        assert!(e.contains("directory"), "{e}");
    }

    #[test]
    fn overrides_apply_by_glob_in_order() {
        let c = PipelineConfig::parse(
            "[bake]\nnormal_bits = 8\n[[override]]\nglob = \"scans/**\"\nposition_bits = 18\n[[override]]\nglob = \"**/hero.glb\"\nposition_bits = 20\n",
            "p.toml",
        )
        .unwrap();
        assert_eq!(c.settings_for(Path::new("props/a.obj")).position_bits, 16);
        assert_eq!(c.settings_for(Path::new("scans/a.obj")).position_bits, 18);
        assert_eq!(c.settings_for(Path::new("scans/x/hero.glb")).position_bits, 20);
        assert_eq!(c.settings_for(Path::new("scans/a.obj")).normal_bits, 8);
        let assets = [PathBuf::from("scans/a.obj")];
        let unmatched: Vec<_> = c.unmatched_overrides(&assets).iter().map(|o| o.glob.as_str()).collect();
        assert_eq!(unmatched, ["**/hero.glb"]);
    }

    #[test]
    fn discovery_walks_up_and_stops_at_a_repository_root() {
        let dir = tempfile::tempdir().unwrap();
        let tree = dir.path().join("outer/repo/assets/scans");
        std::fs::create_dir_all(&tree).unwrap();
        std::fs::write(dir.path().join("outer/pipeline.toml"), "").unwrap();
        std::fs::write(tree.join("a.obj"), "").unwrap();
        // Above the repository (.git) only: not found.
        std::fs::create_dir(dir.path().join("outer/repo/.git")).unwrap();
        assert_eq!(discover(&tree.join("a.obj")).unwrap(), None);
        // The repository root's own file counts, from a file or a directory below it.
        let root_config = dir.path().join("outer/repo/pipeline.toml");
        std::fs::write(&root_config, "").unwrap();
        let found = discover(&tree.join("a.obj")).unwrap().unwrap();
        assert_eq!(found, root_config.canonicalize().unwrap());
        // The nearest one wins.
        let near = dir.path().join("outer/repo/assets/pipeline.toml");
        std::fs::write(&near, "").unwrap();
        assert_eq!(discover(&tree).unwrap().unwrap(), near.canonicalize().unwrap());
    }
}
