//! factory-tests: the workspace's top-level tests, in `tests/`. They drive the crates through their library
//! entry points, as the binaries do:
//!
//! - `end_to_end`: a tiny point-mass run trained into a run folder, its exported policy evaluated and its
//!   learning curve drawn;
//! - `config_errors`: a config or `--set` with an unknown key is refused naming the key (and the file);
//! - `config_doc`: docs/CONFIG.md is the rendering of the config structs (keys, types, defaults, doc
//!   comments), and every key the shipped configs write is in it. `FACTORY_BLESS=1 cargo test -p
//!   factory-tests --release --test config_doc` rewrites the generated part.
//!
//! The library itself is empty.
