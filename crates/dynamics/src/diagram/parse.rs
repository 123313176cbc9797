//! Parsing a diagram definition from TOML: the top-level keys, the `[params]` declarations,
//! the `inputs` table and the `[[block]]` entries with their fields, each checked with an error
//! naming the field. The wiring and graph checks follow in [`super::graph`].

use std::sync::Arc;

use super::expr::Expr;
use super::prim::{self, Kind};
use super::{def::derr, graph, intern, DefError, Diagram, DiagramDef, NodeDef};
use crate::params::ParamSpec;

/// The declared parameters, in declaration order.
pub(super) struct Params {
    pub(super) names: Vec<String>,
    pub(super) specs: Vec<ParamSpec>,
    /// Declared `[min, max]` of each parameter.
    pub(super) allowed: Vec<(f64, f64)>,
    pub(super) defaults: Vec<Option<f64>>,
}

/// A declared input: local name, unit signal, and whether the unit may lack it.
pub(super) struct InDecl {
    pub(super) local: String,
    pub(super) signal: String,
    pub(super) optional: bool,
}

fn as_f64(v: &toml::Value) -> Option<f64> {
    match v {
        toml::Value::Float(f) => Some(*f),
        toml::Value::Integer(i) => Some(*i as f64),
        _ => None,
    }
}

/// Parses and checks a diagram definition. Errors name the field (`block 'x' (lag).t`, …).
pub fn parse_definition(t: &toml::Table) -> Result<DiagramDef, DefError> {
    for key in t.keys() {
        if ![
            "title",
            "inputs",
            "outputs",
            "params",
            "block",
            "exciter_roles",
        ]
        .contains(&key.as_str())
        {
            return Err(derr(
                key.as_str(),
                "unknown key (expected title, inputs, outputs, [params], [[block]], [exciter_roles])",
            ));
        }
    }
    let title = match t.get("title") {
        None => String::new(),
        Some(toml::Value::String(s)) => s.clone(),
        Some(_) => return Err(derr("title", "must be a string")),
    };

    let params = parse_params(t)?;
    exciter_roles(t, &params.names)?;
    let inputs = parse_inputs(t)?;
    let nodes = parse_blocks(t, &params.names)?;
    graph::wire(t, title, params, inputs, nodes)
}

/// The optional `[exciter_roles]` table: which declared parameter plays each exciter role
/// ([`crate::models::exciter::roles::ExciterRoles::from_toml`]); `None` when absent.
pub(super) fn exciter_roles(
    t: &toml::Table,
    params: &[String],
) -> Result<Option<crate::models::exciter::roles::ExciterRoles>, DefError> {
    let Some(v) = t.get("exciter_roles") else {
        return Ok(None);
    };
    let tab = v
        .as_table()
        .ok_or_else(|| derr("exciter_roles", "must be a table of role = parameter"))?;
    crate::models::exciter::roles::ExciterRoles::from_toml(tab, params)
        .map(Some)
        .map_err(|(field, msg)| derr(field, msg))
}

/// The `[params]` table.
fn parse_params(t: &toml::Table) -> Result<Params, DefError> {
    let mut pnames: Vec<String> = vec![];
    let mut specs = vec![];
    let mut allowed = vec![];
    let mut defaults = vec![];
    if let Some(v) = t.get("params") {
        let pt = v
            .as_table()
            .ok_or_else(|| derr("params", "must be a table of parameter declarations"))?;
        for (name, decl) in pt {
            let f = format!("params.{name}");
            if !valid_name(name) {
                return Err(derr(&f, "a parameter name is letters, digits and _"));
            }
            let (mut default, mut range, mut lo, mut hi) =
                (None, None, f64::NEG_INFINITY, f64::INFINITY);
            let (mut unit, mut doc, mut alias) = ("-".to_string(), String::new(), name.clone());
            match decl {
                v if as_f64(v).is_some() => default = as_f64(v),
                toml::Value::Table(d) => {
                    for (k, v) in d {
                        let fk = format!("{f}.{k}");
                        let num = || as_f64(v).ok_or_else(|| derr(&fk, "must be a number"));
                        let text = || {
                            v.as_str()
                                .map(str::to_string)
                                .ok_or_else(|| derr(&fk, "must be a string"))
                        };
                        match k.as_str() {
                            "default" | "value" => default = Some(num()?),
                            "min" => lo = num()?,
                            "max" => hi = num()?,
                            "unit" => unit = text()?,
                            "doc" => doc = text()?,
                            "alias" => alias = text()?,
                            "range" => {
                                let a = v.as_array().filter(|a| a.len() == 2);
                                let r = a.and_then(|a| Some((as_f64(&a[0])?, as_f64(&a[1])?)));
                                match r {
                                    Some((a, b)) if a <= b => range = Some((a, b)),
                                    _ => return Err(derr(&fk, "must be [low, high] with low <= high")),
                                }
                            }
                            _ => {
                                return Err(derr(
                                    &fk,
                                    "unknown key (expected default, range, min, max, unit, doc, alias)",
                                ))
                            }
                        }
                    }
                }
                _ => return Err(derr(&f, "must be a number (the default) or a table { default, range, min, max, unit, doc }")),
            }
            if !(lo <= hi) {
                return Err(derr(&f, format!("min {lo} exceeds max {hi}")));
            }
            if let Some(d) = default {
                if !(d >= lo && d <= hi) {
                    return Err(derr(
                        &f,
                        format!("default {d} lies outside [min, max] = [{lo}, {hi}]"),
                    ));
                }
            }
            if default.is_none() && name.ends_with("_offset") {
                default = Some(0.0);
            }
            let range = range.unwrap_or_else(|| match default {
                Some(d) if d != 0.0 => {
                    let (a, b) = (0.5 * d, 2.0 * d);
                    (a.min(b), a.max(b))
                }
                _ if lo.is_finite() && hi.is_finite() => (lo, hi),
                _ => (0.0, 0.0),
            });
            let typical = default.unwrap_or(0.5 * (range.0 + range.1));
            specs.push(ParamSpec {
                name: intern::str(name),
                alias: intern::str(&alias),
                unit: intern::str(&unit),
                doc: intern::str(if doc.is_empty() {
                    "diagram parameter"
                } else {
                    &doc
                }),
                typical,
                range,
            });
            pnames.push(name.clone());
            allowed.push((lo, hi));
            defaults.push(default);
        }
    }
    Ok(Params {
        names: pnames,
        specs,
        allowed,
        defaults,
    })
}

/// The `inputs` table.
fn parse_inputs(t: &toml::Table) -> Result<Vec<InDecl>, DefError> {
    let mut inputs: Vec<InDecl> = vec![];
    if let Some(v) = t.get("inputs") {
        let it = v
            .as_table()
            .ok_or_else(|| derr("inputs", "must be a table { name = \"unit signal\" }"))?;
        for (local, spec) in it {
            let f = format!("inputs.{local}");
            let (signal, optional) = match spec {
                toml::Value::String(s) => (s.clone(), false),
                toml::Value::Table(d) => {
                    let (signal, optional) = signal_table(
                        d,
                        &f,
                        "expected signal = \"...\" and optional = true|false",
                        |k, v| match (k, v) {
                            ("optional", toml::Value::Boolean(b)) => Some(*b),
                            _ => None,
                        },
                    )?;
                    (signal, optional.unwrap_or(false))
                }
                _ => {
                    return Err(derr(
                        &f,
                        "must be a unit signal name or { signal, optional }",
                    ))
                }
            };
            inputs.push(InDecl {
                local: local.clone(),
                signal,
                optional,
            });
        }
    }
    Ok(inputs)
}

/// The `[[block]]` entries; `pnames` are the declared parameters the fields may use.
fn parse_blocks(t: &toml::Table, pnames: &[String]) -> Result<Vec<NodeDef>, DefError> {
    let lookup = |n: &str| pnames.iter().position(|p| p == n);
    let arr = match t.get("block") {
        Some(toml::Value::Array(a)) => a.clone(),
        Some(_) => return Err(derr("block", "must be an array of tables ([[block]])")),
        None => return Err(derr("block", "missing: a diagram needs [[block]] entries")),
    };
    let mut nodes: Vec<NodeDef> = vec![];
    for (k, item) in arr.iter().enumerate() {
        let bt = item
            .as_table()
            .ok_or_else(|| derr(format!("block[{k}]"), "must be a table"))?;
        let out = match bt.get("out") {
            Some(toml::Value::String(s)) => s.clone(),
            _ => {
                let who = bt
                    .get("name")
                    .and_then(|v| v.as_str())
                    .map(|n| format!("block '{n}'"))
                    .unwrap_or(format!("block[{k}]"));
                return Err(derr(
                    format!("{who}.out"),
                    "missing: every block needs out = \"signal\"",
                ));
            }
        };
        let name = match bt.get("name") {
            None => out.clone(),
            Some(toml::Value::String(s)) => s.clone(),
            Some(_) => return Err(derr(format!("block[{k}].name"), "must be a string")),
        };
        let who = format!("block '{name}'");
        let ty = bt.get("type").and_then(|v| v.as_str()).ok_or_else(|| {
            derr(
                format!("{who}.type"),
                format!("missing (one of: {})", prim::names()),
            )
        })?;
        let info = prim::find(ty).ok_or_else(|| {
            derr(
                format!("{who}.type"),
                format!("unknown primitive '{ty}' (known: {})", prim::names()),
            )
        })?;
        let label = format!("block '{name}' ({})", info.name);
        if nodes.iter().any(|n| n.name == name) {
            return Err(derr(format!("{label}.name"), "two blocks have this name"));
        }
        let ins: Vec<String> = match bt.get("in") {
            None => vec![],
            Some(toml::Value::String(s)) => vec![s.clone()],
            Some(toml::Value::Array(a)) => a
                .iter()
                .map(|v| v.as_str().map(str::to_string))
                .collect::<Option<_>>()
                .ok_or_else(|| {
                    derr(
                        format!("{label}.in"),
                        "must be a signal name or a list of them",
                    )
                })?,
            Some(_) => {
                return Err(derr(
                    format!("{label}.in"),
                    "must be a signal name or a list of them",
                ))
            }
        };
        if !info.arity.accepts(ins.len()) {
            let want = info.arity.describe().0;
            return Err(derr(
                format!("{label}.in"),
                format!("{} takes {want} (got {})", info.name, ins.len()),
            ));
        }
        let mut fields: Vec<Option<Expr>> = vec![None; info.fields.len()];
        let mut field_text: Vec<Option<String>> = vec![None; info.fields.len()];
        let mut list = vec![];
        let mut exps = vec![];
        let mut windup = false;
        let parse_expr = |v: &toml::Value, f: &str| -> Result<(Expr, String), DefError> {
            match v {
                toml::Value::String(s) => {
                    Expr::parse(s, &lookup)
                        .map(|e| (e, s.clone()))
                        .map_err(|m| {
                            derr(
                                f,
                                format!(
                                    "{m} (parameters: {})",
                                    if pnames.is_empty() {
                                        "none declared".to_string()
                                    } else {
                                        pnames.join(", ")
                                    }
                                ),
                            )
                        })
                }
                v => as_f64(v)
                    .map(|x| (Expr::Num(x), format!("{x}")))
                    .ok_or_else(|| derr(f, "must be a number or an expression of the parameters")),
            }
        };
        // The expressions of a list field (`gains`, `x`, `y`), named `field[k]` in errors.
        let parse_list = |items: &[toml::Value], field: &str| -> Result<Vec<Expr>, DefError> {
            items
                .iter()
                .enumerate()
                .map(|(k, v)| parse_expr(v, &format!("{label}.{field}[{k}]")).map(|e| e.0))
                .collect()
        };
        let (mut signs, mut gains, mut xs, mut ys) = (None, None, None, None);
        for (key, v) in bt {
            let f = format!("{label}.{key}");
            match key.as_str() {
                "name" | "type" | "in" | "out" => {}
                "signs" if info.kind == Kind::Sum => {
                    signs = Some(
                        v.as_str()
                            .ok_or_else(|| derr(&f, "must be a string of + and -"))?
                            .to_string(),
                    )
                }
                "gains" if info.kind == Kind::Sum => gains = Some(list_value(v, &f)?),
                "ops" if info.kind == Kind::Product => {
                    let s = v
                        .as_str()
                        .ok_or_else(|| derr(&f, "must be a string of * and /"))?;
                    exps = sign_string(s, ('*', '/'), ins.len()).ok_or_else(|| {
                        derr(
                            &f,
                            format!("must be one * or / per input ({} inputs)", ins.len()),
                        )
                    })?;
                }
                "x" if info.kind == Kind::Pwl => xs = Some(list_value(v, &f)?),
                "y" if info.kind == Kind::Pwl => ys = Some(list_value(v, &f)?),
                "limit" if matches!(info.kind, Kind::Integrator | Kind::Pi | Kind::Pid) => {
                    windup = match v.as_str() {
                        Some("non_windup") => false,
                        Some("windup") => true,
                        _ => return Err(derr(&f, "must be \"non_windup\" or \"windup\"")),
                    }
                }
                _ => {
                    let Some(i) = info.fields.iter().position(|x| x.name == key) else {
                        let mut known: Vec<&str> = info.fields.iter().map(|x| x.name).collect();
                        known.extend(info.options.iter().map(|o| o.0));
                        return Err(derr(
                            &f,
                            format!(
                                "unknown field of {} (fields: {})",
                                info.name,
                                if known.is_empty() {
                                    "none".to_string()
                                } else {
                                    known.join(", ")
                                }
                            ),
                        ));
                    };
                    let (e, txt) = parse_expr(v, &f)?;
                    fields[i] = Some(e);
                    field_text[i] = Some(txt);
                }
            }
        }
        for (i, fs) in info.fields.iter().enumerate() {
            if fs.default.is_none() && fields[i].is_none() {
                return Err(derr(
                    format!("{label}.{}", fs.name),
                    format!("missing: {} needs {} ({})", info.name, fs.name, fs.doc),
                ));
            }
        }
        match info.kind {
            Kind::Sum => {
                if signs.is_some() && gains.is_some() {
                    return Err(derr(
                        format!("{label}.gains"),
                        "give signs or gains, not both",
                    ));
                }
                if let Some(g) = gains {
                    if g.len() != ins.len() {
                        return Err(derr(
                            format!("{label}.gains"),
                            format!("needs one gain per input ({})", ins.len()),
                        ));
                    }
                    list = parse_list(&g, "gains")?;
                } else {
                    let s = signs.unwrap_or_else(|| "+".repeat(ins.len()));
                    let g = sign_string(&s, ('+', '-'), ins.len()).ok_or_else(|| {
                        derr(
                            format!("{label}.signs"),
                            format!(
                                "must be one + or - per input ({} inputs, got \"{s}\")",
                                ins.len()
                            ),
                        )
                    })?;
                    list = g.into_iter().map(Expr::Num).collect();
                }
            }
            Kind::Product if exps.is_empty() => exps = vec![1.0; ins.len()],
            Kind::Pwl => {
                let (Some(xs), Some(ys)) = (xs, ys) else {
                    return Err(derr(
                        format!("{label}.x"),
                        "pwl needs x = [..] and y = [..]",
                    ));
                };
                if xs.len() != ys.len() || xs.len() < 2 {
                    return Err(derr(
                        format!("{label}.y"),
                        "x and y need the same length, at least 2",
                    ));
                }
                list = parse_list(&xs, "x")?;
                list.extend(parse_list(&ys, "y")?);
            }
            _ => {}
        }
        let has_limits = info
            .fields
            .iter()
            .position(|f| f.name == "min")
            .is_some_and(|a| fields[a].is_some() || fields[a + 1].is_some());
        let limited = has_limits
            && matches!(
                info.kind,
                Kind::Lag | Kind::Integrator | Kind::Pi | Kind::Pid
            )
            && !windup;
        nodes.push(NodeDef {
            name,
            info,
            ins,
            out,
            fields,
            field_text,
            list,
            exps,
            windup,
            limited,
        });
    }
    Ok(nodes)
}

/// A `{ signal = "...", <flag> = ... }` declaration of an input or an output (field `f`): the
/// signal and the last flag given. `flag` reads a key other than `signal`, `None` for an
/// unknown key or a bad value, which is an error with the message `expected`.
pub(super) fn signal_table<T>(
    d: &toml::Table,
    f: &str,
    expected: &str,
    flag: impl Fn(&str, &toml::Value) -> Option<T>,
) -> Result<(String, Option<T>), DefError> {
    let mut sig = None;
    let mut value = None;
    for (k, v) in d {
        match (k.as_str(), v) {
            ("signal", toml::Value::String(s)) => sig = Some(s.clone()),
            (k, v) => match flag(k, v) {
                Some(x) => value = Some(x),
                None => return Err(derr(format!("{f}.{k}"), expected)),
            },
        }
    }
    Ok((sig.ok_or_else(|| derr(f, "needs signal = \"...\""))?, value))
}

/// A list field's array (`gains`, `x`, `y`), or an error naming the field `f`.
fn list_value(v: &toml::Value, f: &str) -> Result<Vec<toml::Value>, DefError> {
    Ok(v.as_array()
        .ok_or_else(|| derr(f, "must be a list"))?
        .clone())
}

/// One sign per input from a string of two symbols (`"+-+"`, `"*/"`): `plus_minus.0` gives
/// +1, `plus_minus.1` gives -1. `None` when the string has another length or another symbol.
fn sign_string(s: &str, plus_minus: (char, char), n: usize) -> Option<Vec<f64>> {
    let (plus, minus) = plus_minus;
    if s.chars().count() != n || s.chars().any(|c| c != plus && c != minus) {
        return None;
    }
    Some(
        s.chars()
            .map(|c| if c == plus { 1.0 } else { -1.0 })
            .collect(),
    )
}

fn valid_name(s: &str) -> bool {
    !s.is_empty()
        && s.chars().all(|c| c.is_alphanumeric() || c == '_')
        && !s.chars().next().is_some_and(|c| c.is_ascii_digit())
}

/// Reads a diagram definition from a TOML table and makes the block.
pub fn from_table(t: &toml::Table) -> Result<Diagram, DefError> {
    Ok(Diagram::new(Arc::new(parse_definition(t)?)))
}
