//! Checks that a Rust-side GPU mirror (a `#[repr(C)]` Pod struct uploaded as a uniform or a storage-buffer
//! element) has the layout naga gives the WGSL struct it mirrors: the same size and every member at the same
//! byte offset. A mirror that drifts from its shader reads garbage or binds a uniform too small for the
//! struct (a uniform 8 bytes short, two pad words missing, is the case this guards against).
//!
//! The Rust side is described by [`gpu_mirror!`](crate::gpu_mirror), which takes the offsets from
//! `std::mem::offset_of!`; the WGSL side is laid out by naga's [`Layouter`](naga::proc::Layouter). Members
//! are matched by name. WGSL members whose name starts with `_` are padding: the size and the offset of the
//! next member already pin them, so a mirror may leave them out (or spell them as one array).
//!
//! ```
//! use factory_engine::gpu::layout::assert_mirror;
//! #[repr(C)]
//! struct ParamsGpu {
//!     count: u32,
//!     _pad: [u32; 3],
//!     gravity: [f32; 4],
//! }
//! let wgsl = "struct Params { count: u32, _pad0: u32, _pad1: u32, _pad2: u32, gravity: vec4<f32> }";
//! assert_mirror(wgsl, "Params", &factory_engine::gpu_mirror!(ParamsGpu { count, gravity }));
//! ```

/// A Rust mirror's layout: its name, `size_of` and the `offset_of` of the fields it lists.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Mirror {
    /// The Rust type's name (for reports).
    pub name: &'static str,
    /// `std::mem::size_of` of the type [bytes].
    pub size: usize,
    /// (field name, `std::mem::offset_of!` [bytes]) of each listed field, named as the WGSL member.
    pub fields: Vec<(&'static str, usize)>,
}

/// The [`Mirror`] of a `#[repr(C)]` type from its field names (each named as the WGSL member it mirrors):
/// `gpu_mirror!(ParamsGpu { count, gravity })`.
#[macro_export]
macro_rules! gpu_mirror {
    ($ty:ty { $($field:ident),* $(,)? }) => {
        $crate::gpu::layout::Mirror {
            name: stringify!($ty),
            size: ::std::mem::size_of::<$ty>(),
            fields: vec![$((stringify!($field), ::std::mem::offset_of!($ty, $field))),*],
        }
    };
}

/// The declaration of struct `name` in WGSL `source`, after those of the structs its members use
/// (transitively), comments removed: a module naga parses on its own, whatever functions, bindings or
/// pipeline constants the rest of the source needs. Lets a test lay out a struct from the one file of a
/// kernel that declares it, though the kernel is assembled from several.
pub fn struct_declarations(source: &str, name: &str) -> String {
    let text = strip_comments(source);
    let mut decls: Vec<(&str, &str)> = Vec::new();
    let mut rest = text.as_str();
    while let Some(at) = find_keyword(rest, "struct") {
        let decl = &rest[at..];
        let (Some(open), Some(close)) = (decl.find('{'), decl.find('}')) else { break };
        if close < open {
            break;
        }
        decls.push((decl["struct".len()..open].trim(), &decl[..close + 1]));
        rest = &decl[close + 1..];
    }
    // Depth-first from `name`: a struct's dependencies go out before it.
    fn visit<'a>(name: &str, decls: &[(&'a str, &'a str)], out: &mut Vec<&'a str>, seen: &mut Vec<String>) {
        if seen.iter().any(|s| s == name) {
            return;
        }
        seen.push(name.to_string());
        let Some(&(_, decl)) = decls.iter().find(|(n, _)| *n == name) else { return };
        let body = &decl[decl.find('{').unwrap_or(0)..];
        for &(other, _) in decls {
            if other != name && find_keyword(body, other).is_some() {
                visit(other, decls, out, seen);
            }
        }
        out.push(decl);
    }
    let mut out = Vec::new();
    visit(name, &decls, &mut out, &mut Vec::new());
    out.join("\n")
}

/// `source` with `//` line comments and `/* */` block comments (nested, as WGSL allows) replaced by spaces.
fn strip_comments(source: &str) -> String {
    let bytes = source.as_bytes();
    let mut out = String::with_capacity(source.len());
    let (mut i, mut depth) = (0, 0usize);
    let mut start = 0;
    while i < bytes.len() {
        if depth == 0 && bytes[i..].starts_with(b"//") {
            out.push_str(&source[start..i]);
            while i < bytes.len() && bytes[i] != b'\n' {
                i += 1;
            }
            start = i;
        } else if bytes[i..].starts_with(b"/*") {
            if depth == 0 {
                out.push_str(&source[start..i]);
            }
            depth += 1;
            i += 2;
        } else if depth > 0 && bytes[i..].starts_with(b"*/") {
            depth -= 1;
            i += 2;
            if depth == 0 {
                out.push(' ');
                start = i;
            }
        } else {
            i += 1;
        }
    }
    if depth == 0 {
        out.push_str(&source[start..]);
    }
    out
}

/// Byte index of the first `word` in `text` that stands as a whole word.
fn find_keyword(text: &str, word: &str) -> Option<usize> {
    let is_ident = |c: u8| c.is_ascii_alphanumeric() || c == b'_';
    let bytes = text.as_bytes();
    let mut from = 0;
    while let Some(k) = text[from..].find(word) {
        let at = from + k;
        let end = at + word.len();
        if (at == 0 || !is_ident(bytes[at - 1])) && (end == bytes.len() || !is_ident(bytes[end])) {
            return Some(at);
        }
        from = end;
    }
    None
}

/// naga's layout of struct `name` in WGSL `source` (size, then (member, offset) in order); the source is cut
/// down to the struct and those it uses first ([`struct_declarations`]).
pub fn wgsl_struct_layout(source: &str, name: &str) -> Result<(usize, Vec<(String, usize)>), String> {
    let structs = struct_declarations(source, name);
    let module = naga::front::wgsl::parse_str(&structs).map_err(|e| e.emit_to_string(&structs))?;
    let mut layouter = naga::proc::Layouter::default();
    layouter.update(module.to_ctx()).map_err(|e| format!("naga cannot lay out the structs: {e:?}"))?;
    let Some((handle, ty)) = module.types.iter().find(|(_, t)| t.name.as_deref() == Some(name)) else {
        return Err(format!("the WGSL source declares no struct `{name}`"));
    };
    let naga::TypeInner::Struct { members, .. } = &ty.inner else {
        return Err(format!("`{name}` is not a struct"));
    };
    let members = members.iter().map(|m| (m.name.clone().unwrap_or_default(), m.offset as usize)).collect::<Vec<_>>();
    Ok((layouter[handle].size as usize, members))
}

/// Compares `mirror` with WGSL struct `name` in `source`: the sizes, each listed field's offset against the
/// WGSL member of that name, and that every WGSL member but padding (`_` names) is listed. Every mismatch
/// is named in the error, one per line.
pub fn check_mirror(source: &str, name: &str, mirror: &Mirror) -> Result<(), String> {
    let (size, members) = wgsl_struct_layout(source, name)?;
    let mut errors = Vec::new();
    if size != mirror.size {
        errors.push(format!(
            "size: WGSL `{name}` is {size} bytes, Rust `{}` is {} ({})",
            mirror.name,
            mirror.size,
            if mirror.size < size { format!("{} bytes short", size - mirror.size) } else { "larger".into() }
        ));
    }
    for &(field, offset) in &mirror.fields {
        match members.iter().find(|(m, _)| m == field) {
            None => errors.push(format!("field `{field}`: WGSL `{name}` has no member of that name")),
            Some((_, o)) if *o != offset => {
                errors.push(format!("field `{field}`: WGSL offset {o}, Rust offset {offset}"))
            }
            Some(_) => {}
        }
    }
    for (member, offset) in &members {
        if !member.starts_with('_') && !mirror.fields.iter().any(|(f, _)| f == member) {
            errors.push(format!("member `{member}` (WGSL offset {offset}) has no field in `{}`", mirror.name));
        }
    }
    if errors.is_empty() {
        Ok(())
    } else {
        Err(format!("`{}` does not mirror WGSL `{name}`:\n{}", mirror.name, errors.join("\n")))
    }
}

/// [`check_mirror`], panicking with its report.
#[track_caller]
pub fn assert_mirror(source: &str, name: &str, mirror: &Mirror) {
    if let Err(e) = check_mirror(source, name, mirror) {
        panic!("{e}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const WGSL: &str = "
        // A uniform { with a brace in a comment.
        struct Params {
            world_count: u32,
            dt: f32,
            _pad0: u32,
            _pad1: u32,
            /* block comment } */ gravity: vec4<f32>,
            inertia: mat3x3<f32>,
            flags: u32,
        }
        @group(0) @binding(0) var<uniform> params: Params;
        fn uses_undeclared() -> f32 { return undeclared_binding[0]; }
    ";

    #[repr(C)]
    struct ParamsGpu {
        world_count: u32,
        dt: f32,
        _pad: [u32; 2],
        gravity: [f32; 4],
        inertia: [[f32; 4]; 3],
        flags: u32,
        _tail: [u32; 3],
    }

    /// The same struct with the two pad words in the middle forgotten: every later member 8 bytes early
    /// and the whole 8 bytes short.
    #[repr(C)]
    struct ParamsGpuEightBytesShort {
        world_count: u32,
        dt: f32,
        gravity: [f32; 4],
        inertia: [[f32; 4]; 3],
        flags: u32,
        _tail: [u32; 3],
    }

    #[test]
    fn a_faithful_mirror_passes() {
        // naga: 4 + 4 + 2 * 4 = 16, gravity at 16, the mat3x3's three 16-byte columns at 32, flags at 80,
        // the size rounded up to the 16-byte alignment: 96.
        assert_eq!(
            wgsl_struct_layout(WGSL, "Params").unwrap(),
            (
                96,
                [("world_count", 0), ("dt", 4), ("_pad0", 8), ("_pad1", 12), ("gravity", 16), ("inertia", 32)]
                    .into_iter()
                    .chain([("flags", 80)])
                    .map(|(n, o)| (n.to_string(), o))
                    .collect()
            )
        );
        assert_mirror(WGSL, "Params", &crate::gpu_mirror!(ParamsGpu { world_count, dt, gravity, inertia, flags }));
    }

    /// The regression: a uniform mirror 8 bytes short of its WGSL struct is reported, with the shortfall and
    /// each member it displaced.
    #[test]
    fn a_mirror_8_bytes_short_is_reported() {
        let short = crate::gpu_mirror!(ParamsGpuEightBytesShort { world_count, dt, gravity, inertia, flags });
        assert_eq!(short.size, 88);
        let e = check_mirror(WGSL, "Params", &short).unwrap_err();
        assert!(
            e.contains("size: WGSL `Params` is 96 bytes, Rust `ParamsGpuEightBytesShort` is 88 (8 bytes short)"),
            "{e}"
        );
        assert!(e.contains("field `gravity`: WGSL offset 16, Rust offset 8"), "{e}");
        assert!(e.contains("field `inertia`: WGSL offset 32, Rust offset 24"), "{e}");
        assert!(e.contains("field `flags`: WGSL offset 80, Rust offset 72"), "{e}");
        assert!(!e.contains("world_count") && !e.contains("`dt`"), "{e}");
    }

    /// A WGSL member the mirror does not list, a listed field the WGSL struct lacks, and an absent struct are
    /// each reported by name.
    #[test]
    fn missing_members_and_structs_are_named() {
        let partial = crate::gpu_mirror!(ParamsGpu { world_count, dt, gravity, inertia });
        let e = check_mirror(WGSL, "Params", &partial).unwrap_err();
        assert!(e.contains("member `flags` (WGSL offset 80) has no field in `ParamsGpu`"), "{e}");
        let renamed = WGSL.replace("flags: u32", "bits: u32");
        let full = crate::gpu_mirror!(ParamsGpu { world_count, dt, gravity, inertia, flags });
        let e = check_mirror(&renamed, "Params", &full).unwrap_err();
        assert!(e.contains("field `flags`: WGSL `Params` has no member of that name"), "{e}");
        assert!(check_mirror(WGSL, "Missing", &full).unwrap_err().contains("declares no struct `Missing`"));
    }

    #[test]
    fn struct_declarations_keep_the_struct_and_those_it_uses() {
        let src = "const N: u32 = 4u; /* struct Fake { x: u32 } */ struct A { x: u32 }\n// struct B { y: f32 }\n\
                   fn f() -> u32 { return 1u; }\nstruct my_struct_b { a: array<A, 2>, v: vec4<f32> }\n\
                   struct C { b: my_struct_b, ab: u32 }\nstruct Unused { z: Missing }";
        let words = |s: String| s.split_whitespace().collect::<Vec<_>>().join(" ");
        assert_eq!(words(struct_declarations(src, "A")), "struct A { x: u32 }");
        assert_eq!(
            words(struct_declarations(src, "C")),
            "struct A { x: u32 } struct my_struct_b { a: array<A, 2>, v: vec4<f32> } struct C { b: my_struct_b, ab: u32 }"
        );
        assert_eq!(wgsl_struct_layout(src, "C").unwrap().0, 48);
        assert_eq!(struct_declarations(src, "Absent"), "");
    }
}
