//! `pipeline.toml`: the bake settings file. Unknown keys and bad values are errors that name
//! the key and the file.

use crate::settings::BakeSettings;
use serde::Deserialize;
use std::path::Path;

/// The embedded defaults: the repository's `pipeline.toml`.
pub const DEFAULT_PIPELINE_TOML: &str = include_str!("../../pipeline.toml");

/// A parsed `pipeline.toml`.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PipelineConfig {
    /// `[bake]`: settings of every bake.
    #[serde(default)]
    pub bake: BakeSettings,
    /// `[output]`: where results go.
    #[serde(default)]
    pub output: OutputConfig,
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

impl PipelineConfig {
    /// Parses TOML text; `origin` names the file in errors.
    pub fn parse(text: &str, origin: &str) -> Result<PipelineConfig, String> {
        let config: PipelineConfig = toml::from_str(text).map_err(|e| format!("{origin}: {e}"))?;
        config.bake.check().map_err(|e| format!("{origin}: [bake] {e}"))?;
        Ok(config)
    }

    /// Loads `path`.
    pub fn load(path: &Path) -> Result<PipelineConfig, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        PipelineConfig::parse(&text, &path.display().to_string())
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
    }
}
