//! `itaipu-calib models`: the model library, its parameters and ports, and the diagram
//! primitives.

use itaipu_dynamics::registry;

use crate::CliError;

/// Lists every model, or the one named (`diagram`: the diagram primitives); `table`: the
/// library as docs/model-library.md's Markdown table.
pub fn cmd_models(name: Option<&str>, table: bool) -> Result<(), CliError> {
    if table {
        print!("{}", registry::library_table());
        return Ok(());
    }
    let models: Vec<_> = match name.map(registry::listing) {
        Some(Ok(registry::Listing::DiagramPrimitives)) => {
            print!("{}", itaipu_dynamics::diagram::describe_primitives());
            return Ok(());
        }
        Some(Ok(registry::Listing::Model(m))) => vec![m],
        Some(Err(msg)) => return Err(CliError::new(2, msg)),
        None => registry::all().collect(),
    };
    for m in models {
        let b = m.create();
        println!("{} [{}]: {}", m.name, m.role.section(), m.summary);
        println!("  follows: {}", m.reference);
        if let Some(r) = &m.dyr {
            println!(
                "  .dyr:   IBUS '{}' ID {} /",
                m.name,
                r.field_names(b.as_ref()).join(" ")
            );
        }
        if let Some(roles) = registry::roles_line(b.as_ref()) {
            println!("  roles:  {roles}");
        }
        println!("  states: {}", b.state_names().join(", "));
        let ports: Vec<String> = b
            .ports()
            .iter()
            .map(|p| {
                format!(
                    "{}{}",
                    p.name,
                    if p.dir == itaipu_dynamics::block::Dir::In {
                        "(in)"
                    } else {
                        "(out)"
                    }
                )
            })
            .collect();
        println!("  ports:  {}", ports.join(", "));
        for s in b.params().specs() {
            println!(
                "  {:<14} {:<8} {:>6}  typical {:<8} range {:>7}-{:<7} {}",
                s.name, s.alias, s.unit, s.typical, s.range.0, s.range.1, s.doc
            );
        }
        println!();
    }
    if name.is_none() {
        print!("{}", itaipu_dynamics::diagram::describe_primitives());
    }
    Ok(())
}
